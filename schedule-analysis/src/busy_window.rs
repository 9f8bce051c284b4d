//! The busy-window fixed point that both analyses share: preemptive for the board tasks, non-preemptive for the
//! CAN frames. Allocation-free; the caller lends a scratch slice of [`Counter`]s (each interferer's next
//! activation) so that an iteration divides only for the interferers with a new activation in the grown window.
//!
//! Notation (docs/analysis.md has the derivation): a subject with cost `C` per instance, `n` instances per
//! activation (frames per sample on the bus, 1 on a board), period `T`, release jitter `J` and blocking `B`,
//! interfered with by streams `k` with cost `C_k` per activation, period `T_k` and jitter `J_k`.
//! An interferer's activations before `x` number `⌈(x + J_k) / T_k⌉` (releases strictly before `x`).
//!
//! * Preemptive (RTIC, SRP): `w(q) = B + (q+1)·C + Σ_k ⌈(w(q) + J_k)/T_k⌉·C_k`, `R(q) = w(q) − q·T + J`;
//!   the window closes after the first `q` with `w(q) + J ≤ (q+1)·T`.
//! * Non-preemptive (CAN, Davis et al. 2007): the level busy period
//!   `t = B + Σ_{k ∪ self} ⌈(t + J_k)/T_k⌉·C_k` holds `Q = ⌈(t + J)/T⌉` activations; for every instance `q`
//!   (activation `q / n`) `w(q) = B + q·C + Σ_k ⌈(w(q) + J_k + τ)/T_k⌉·C_k` and
//!   `R(q) = J + w(q) + C − ⌊q/n⌋·T`, with `τ` one bit time.
//!
//! The iterations start from a lower bound of the least fixed point derived from the utilisation
//! (`w ≥ (B + C + Σ J_k·U_k) / (1 − U)`), which leaves the result exact and saves most iterations on large sets.

use core::fmt;

use crate::time::Time;

/// Something that arrives periodically or sporadically and costs processor or bus time when it does.
pub trait Activations {
    /// Cost of one activation, all its instances included (a proximity-ring sample is 8 frames).
    fn activation_cost(&self) -> Time;
    /// Period, or minimum inter-arrival time for sporadic activations.
    fn period(&self) -> Time;
    /// Release jitter: how late after its nominal time an activation may become ready.
    fn jitter(&self) -> Time;
}

/// Incremental count of one interferer's activations: an iteration compares the grown window with each
/// interferer's next activation and divides only for those it passed. 32-bit fields: windows, periods, costs and
/// jitters below 4.29 s (the boards' case) cost the Cortex-M3 single instructions; a window with anything larger
/// is summed by dividing instead (the same numbers).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counter {
    /// Nominal instant of the next activation not yet counted, `count·T − J`, or `u32::MAX` when at or beyond it.
    next: u32,
    /// Activations counted so far.
    count: u32,
    /// The interferer's cost per activation, period and jitter, copied at the start of the window.
    cost: u32,
    period: u32,
    jitter: u32,
}

impl Counter {
    /// No activation counted, of nothing: a working array's initial value (`const`, so a whole array of it is one
    /// zeroing, not one call per element).
    pub const ZERO: Counter = Counter {
        next: 0,
        count: 0,
        cost: 0,
        period: 0,
        jitter: 0,
    };

    /// The counter of an interferer (cost `c`, period `t`, jitter `j`) at window `x`: `⌈(x + J)/T⌉` activations
    /// (`None` outside 32 bits).
    #[inline(always)]
    fn at(x: u32, c: u64, t: u64, j: u64) -> Option<Counter> {
        let (c, t, j) = (
            u32::try_from(c).ok()?,
            u32::try_from(t).ok()?,
            u32::try_from(j).ok()?,
        );
        let (count, next) = count_at(x, t, j)?;
        Some(Counter {
            next,
            count,
            cost: c,
            period: t,
            jitter: j,
        })
    }
}

/// What is analysed: one task (or one CAN message) against the streams that may delay it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Subject {
    /// Cost of one instance (one job, one frame).
    pub cost: Time,
    /// Instances queued together per activation (frames per sample); 1 for a board task.
    pub instances_per_activation: u32,
    /// Period or minimum inter-arrival time.
    pub period: Time,
    /// Release (or queuing) jitter.
    pub jitter: Time,
    /// Blocking by lower-priority work: an SRP critical section, or one lower-priority frame.
    pub blocking: Time,
    /// A value known not to exceed the first instance's window (the least fixed point for instance 0), e.g. that
    /// of a higher-priority stream whose interferers are a subset of this one's; `ZERO` when none is known.
    /// Only speeds the iteration up: a start at or below the least fixed point gives the same result.
    pub known_first_window: Time,
    /// The same for the non-preemptive level busy period.
    pub known_busy_period: Time,
    /// Its own utilisation when the caller has it already ([`Share::utilisation`] of `cost × instances` per
    /// `period`); `None`: worked out here.
    pub known_utilisation: Option<u64>,
}

impl Subject {
    /// A subject without start hints.
    pub fn new(
        cost: Time,
        instances_per_activation: u32,
        period: Time,
        jitter: Time,
        blocking: Time,
    ) -> Subject {
        Subject {
            cost,
            instances_per_activation,
            period,
            jitter,
            blocking,
            known_first_window: Time::ZERO,
            known_busy_period: Time::ZERO,
            known_utilisation: None,
        }
    }
}

/// How the resource is shared.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Discipline {
    /// A processor under fixed-priority preemptive scheduling; equal-priority work runs to completion.
    Preemptive,
    /// A CAN bus: a frame once started is never interrupted; `bit_time` is the arbitration resolution.
    NonPreemptive {
        /// One bit time τ: a higher-priority frame queued up to τ after the bus becomes idle still wins.
        bit_time: Time,
    },
}

/// Where the analysis gives up on a busy window that keeps growing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// A busy window longer than this is reported as unbounded.
    pub horizon: Time,
    /// Fixed-point iterations one response may take ([`AnalysisError::IterationLimit`] beyond):
    /// [`MAX_ITERATIONS`] by default; the admission check gives each response what is left of its per-decision
    /// budget.
    pub iterations: u64,
}

impl Default for Limits {
    /// One minute: far beyond any AMiRo period, small enough to stop quickly.
    fn default() -> Self {
        Limits {
            horizon: Time::from_us(60_000_000),
            iterations: MAX_ITERATIONS,
        }
    }
}

/// The worst case found in the busy window.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Response {
    /// Worst-case response time, measured from the nominal activation (release jitter included).
    pub wcrt: Time,
    /// Which instance of the busy window (0-based) met the worst case.
    pub worst_instance: u64,
    /// Instances in the busy window.
    pub instances: u64,
    /// Length of the busy window.
    pub busy_window: Time,
    /// Interference by the other streams in the worst instance's window.
    pub interference: Time,
    /// The first instance's window: its completion (preemptive) or transmission start (non-preemptive) after the
    /// critical instant — a start hint for lower-priority streams.
    pub first_window: Time,
    /// Fixed-point iterations this bound took (one per evaluation of the interference sum): the measure of the
    /// analysis's cost that an on-chip admission check reports and bounds.
    pub iterations: u64,
}

/// Why no response time exists (or none could be computed).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AnalysisError {
    /// The utilisation at this priority level exceeds 1 (or a period is zero): the busy window never closes.
    Overload,
    /// The busy window grew beyond [`Limits::horizon`] (utilisation at or within rounding of 1).
    BeyondHorizon,
    /// The set was not ordered by priority as the function requires.
    NotSorted,
    /// The index does not name an element of the set.
    NoSuchIndex,
    /// A time in the iteration does not fit in 64-bit nanoseconds (inputs near [`Time::MAX`]): no bound is
    /// claimed rather than a saturated one.
    Overflow,
    /// The fixed point needed more than [`MAX_ITERATIONS`] iterations: reported as unbounded, so the analysis
    /// ends in bounded time on any input.
    IterationLimit,
}

impl AnalysisError {
    /// Whether the error means "no bound exists" rather than a usage mistake.
    pub fn is_unbounded(self) -> bool {
        matches!(
            self,
            AnalysisError::Overload
                | AnalysisError::BeyondHorizon
                | AnalysisError::Overflow
                | AnalysisError::IterationLimit
        )
    }
}

impl fmt::Display for AnalysisError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            AnalysisError::Overload => {
                "unbounded: utilisation at this priority level exceeds 100 %"
            }
            AnalysisError::BeyondHorizon => {
                "unbounded: the busy window grows beyond the analysis horizon"
            }
            AnalysisError::NotSorted => "the set is not ordered by priority",
            AnalysisError::NoSuchIndex => "no element with that index",
            AnalysisError::Overflow => {
                "unbounded: a time exceeds the analysis's 64-bit nanosecond range"
            }
            AnalysisError::IterationLimit => {
                "unbounded: the fixed point needs more iterations than the analysis allows"
            }
        })
    }
}

/// Utilisations are fixed-point integers: `1 << UTIL_BITS` is 100 %. No floating point anywhere in the fixed point
/// (the Cortex-M3 has no FPU: soft-float `f64` cost the chip kilobytes of flash and most of an admission
/// decision's time), and integer sums are exact, so a load summed once per priority level and one summed per task
/// are the same number.
pub const UTIL_BITS: u32 = 24;
/// 100 % utilisation in [`UTIL_BITS`] fixed point.
pub const UTIL_ONE: u64 = 1 << UTIL_BITS;
/// The utilisation bound is only used to start the iteration when `1 − U` is at least 1/this.
const MIN_SLACK_FOR_BOUND: u64 = 1000;
/// A product or sum in the start bound larger than this (ns, about 18 min) is left out of it (a smaller start
/// is still a safe one), so that its fixed-point products never overflow.
const BOUND_LIMIT: u64 = 1 << 40;
/// Instances examined in one busy window before giving up.
const MAX_INSTANCES: u64 = 50_000_000;
/// Fixed-point iterations (evaluations of the interference sum) one response time may take before it is
/// reported as unbounded ([`AnalysisError::IterationLimit`]). Far above any AMiRo set (tens of iterations per
/// task), it bounds the running time of the analysis on any input.
pub const MAX_ITERATIONS: u64 = 10_000_000;

#[inline(always)]
fn add(a: u64, b: u64) -> Result<u64, AnalysisError> {
    a.checked_add(b).ok_or(AnalysisError::Overflow)
}

#[inline(always)]
fn mul(a: u64, b: u64) -> Result<u64, AnalysisError> {
    if (a | b) >> 32 == 0 {
        // Both below 2^32 (the boards' common case): one 32 × 32 → 64-bit multiply, which cannot overflow,
        // instead of the Cortex-M3's checked 64 × 64 sequence.
        return Ok(u64::from(a as u32) * u64::from(b as u32));
    }
    mul_wide(a, b)
}

/// The rare case of [`mul`], out of line: the checked 64 × 64 sequence is long on the Cortex-M3, and inlined at
/// each of `mul`'s dozen sites it cost the boards about 1.5 KB of flash.
#[inline(never)]
#[cold]
fn mul_wide(a: u64, b: u64) -> Result<u64, AnalysisError> {
    a.checked_mul(b).ok_or(AnalysisError::Overflow)
}

/// `⌈a / b⌉`; total: a zero `b` (which no caller passes: periods are checked first) gives `u64::MAX`, so no
/// division-by-zero panic is linked into the boards' admission check.
#[inline(always)]
fn ceil_div(a: u64, b: u64) -> u64 {
    if a == 0 {
        0
    } else if let (Ok(a32), Ok(b32)) = (u32::try_from(a), u32::try_from(b)) {
        // The common case on the boards (windows and periods below 4.29 s): the Cortex-M3's hardware divide
        // instead of the 64-bit software routine.
        (a32 - 1)
            .checked_div(b32)
            .map_or(u64::MAX, |q| u64::from(q) + 1)
    } else {
        (a - 1).checked_div(b).map_or(u64::MAX, |q| q + 1)
    }
}

/// A job's terms in [`linear_bound`], each rounded *up*: its cost, its utilisation `⌈C/T · 2^UTIL_BITS⌉` and its
/// jitter's share `⌈J · ⌈U⌉⌉` (ns); summed over a set of interferers. Sums saturate: a saturated term only makes
/// the bound larger (it then meets no deadline, and the exact analysis decides).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LinearTerms {
    /// `Σ C_k` (ns).
    pub cost: u64,
    /// `Σ ⌈U_k · 2^UTIL_BITS⌉`.
    pub utilisation: u64,
    /// `Σ ⌈J_k · U_k⌉` (ns), with `U_k` rounded up as above.
    pub jitter_load: u64,
}

impl LinearTerms {
    /// The terms of a job of cost `c`, period `t` and release jitter `j` (ns) whose [`Load`] as an interferer is
    /// `load` ([`Share::load`]: its utilisation and jitter's share rounded down, worked out for the exact analysis
    /// anyway), mostly without a multiply: nothing for one that costs nothing (the exact analysis skips it too); a
    /// utilisation of 100 % for one the bound cannot take (a zero period, or a cost of a whole period), so that no
    /// bound is found beside it.
    #[inline]
    pub fn of(load: Load, c: u64, t: u64, j: u64) -> LinearTerms {
        if c == 0 {
            return LinearTerms::default();
        }
        // Below 2^32 ns the load's terms are the exact floors (the 32-bit long division; `J·u` within 64 bits for
        // jitters below 2^40 ns): `⌈U⌉ ≤ u + 1`, and `J·⌈U⌉ ≤ J·u + J` rounds up to at most
        // `⌊J·u⌋ + ⌊J/2^24⌋ + 2`. Beyond, `c · 2^24 / t ≤ c / 2^8` bounds the utilisation, and a multiply the rest.
        let exact = t >> 32 == 0;
        let utilisation = if !exact {
            (c >> (32 - UTIL_BITS)).saturating_add(1)
        } else if c < t {
            load.utilisation + 1
        } else {
            UTIL_ONE
        };
        let jitter_load = if exact && j >> 40 == 0 {
            load.jitter_load + (j >> UTIL_BITS) + 2
        } else {
            (j.saturating_mul(utilisation) >> UTIL_BITS).saturating_add(1)
        };
        LinearTerms {
            cost: c,
            utilisation,
            jitter_load,
        }
    }

    /// Both sets of terms together.
    pub fn plus(self, other: LinearTerms) -> LinearTerms {
        LinearTerms {
            cost: self.cost.saturating_add(other.cost),
            utilisation: self.utilisation.saturating_add(other.utilisation),
            jitter_load: self.jitter_load.saturating_add(other.jitter_load),
        }
    }

    /// These terms without `part` (which must be one of the summed terms).
    pub fn minus(self, part: LinearTerms) -> LinearTerms {
        LinearTerms {
            cost: self.cost.saturating_sub(part.cost),
            utilisation: self.utilisation.saturating_sub(part.utilisation),
            jitter_load: self.jitter_load.saturating_sub(part.jitter_load),
        }
    }
}

/// A closed-form upper bound on the first instance's window of a preemptive subject (cost `c`, blocking `b`, both
/// ns) delayed by interferers whose [`LinearTerms`] sum to `others` — Bini, Nguyen, Richard & Baruah's linear bound
/// in its simple form: since `⌈(w + J_k)/T_k⌉·C_k ≤ C_k + U_k·(w + J_k)`, the window's demand
/// `b + c + Σ ⌈(w + J_k)/T_k⌉·C_k` is at most `w` at `w̄ = (b + c + Σ (C_k + U_k J_k)) / (1 − Σ U_k)`, so the least
/// fixed point — the exact analysis's window — is at most `w̄`. Every term is rounded up, and `w̄` too. O(1) given
/// the sums, no iteration, one 32-bit long division. `None` when the interferers' utilisation reaches 100 % or the
/// numerator leaves 32 bits (4.29 s).
///
/// When `w̄ + J` fits in the subject's period, its busy window holds one instance and its worst-case response is at
/// most `w̄ + J` (the test `the_linear_bound_is_above_the_exact_response` holds both to the exact analysis).
pub fn linear_bound(c: u64, b: u64, others: LinearTerms) -> Option<u64> {
    let slack = UTIL_ONE
        .checked_sub(others.utilisation)
        .filter(|&s| s > 0)?;
    let numerator = b
        .saturating_add(c)
        .saturating_add(others.cost)
        .saturating_add(others.jitter_load);
    // ⌈n · 2^UTIL_BITS / slack⌉ ≤ ⌊…⌋ + 1.
    (numerator >> 32 == 0).then(|| shifted_quotient(numerator, slack) + 1)
}

/// The load of a set of interferers that starts the fixed point and detects overload: `Σ U_k` and `Σ J_k·U_k`,
/// each term rounded *down* (so the start derived from it stays at or below the least fixed point, and a load
/// above 100 % is a real overload). Sums of terms are exact, so a caller that analyses many subjects against
/// prefixes of one set (every task of a board) sums each level once ([`Load::plus`], [`Load::minus`]) and gets
/// the very numbers [`response_time`] would sum per subject.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Load {
    /// `Σ ⌊U_k · 2^UTIL_BITS⌋` (each term at most [`UTIL_ONE`]).
    pub utilisation: u64,
    /// `Σ ⌊J_k · U_k⌋` in ns (each term at most 2^40).
    pub jitter_load: u64,
    /// Interferers with a cost and a zero period (overload whatever else).
    pub zero_periods: u64,
}

/// An activation source's share of the processor or bus: its utilisation, worked out once (one division) so that
/// a caller that needs it again — as an interferer's [`Load`] with a changing jitter, as the subject's own
/// utilisation ([`Subject::known_utilisation`]) — does not divide again.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Share {
    /// `⌊c/t · 2^UTIL_BITS⌋` (at most [`UTIL_ONE`] = 2^24, so 32 bits), or [`ZERO_PERIOD`] alone for a zero period.
    utilisation: u32,
}

/// [`Share`]'s mark of a zero period, a bit above any utilisation: 4 bytes a share, not a `u64` and a flag (16 B), as
/// the on-chip check keeps one per job of a board (docs/analysis.md, "The on-chip admission check").
const ZERO_PERIOD: u32 = 1 << 31;

impl Share {
    /// The share of work `cost` every `period` (nothing when it costs nothing; a zero period overloads).
    pub fn of(cost: Time, period: Time) -> Share {
        let (c, t) = (cost.as_ns(), period.as_ns());
        if c == 0 {
            Share::default()
        } else if t == 0 {
            Share {
                utilisation: ZERO_PERIOD,
            }
        } else {
            Share::with_utilisation(utilisation_floor(c, t))
        }
    }

    /// The share whose utilisation `utilisation` was worked out before, as [`Share::of`] works it out (a table's,
    /// built on the host): no division. A utilisation is at most [`UTIL_ONE`] (one such interferer overloads any
    /// level already); a larger figure is taken as [`UTIL_ONE`], which fits in 32 bits below the zero period's mark.
    pub fn with_utilisation(utilisation: u64) -> Share {
        Share {
            utilisation: utilisation.min(UTIL_ONE) as u32,
        }
    }

    /// Its utilisation, `⌊c/t · 2^UTIL_BITS⌋` capped at [`UTIL_ONE`] (0 for a zero period).
    pub fn utilisation(self) -> u64 {
        u64::from(self.utilisation & !ZERO_PERIOD)
    }

    /// Its load as an interferer with release jitter `jitter`: exactly [`Load::of`].
    pub fn load(self, jitter: Time) -> Load {
        if self.utilisation == ZERO_PERIOD {
            return Load {
                zero_periods: 1,
                ..Load::default()
            };
        }
        Load {
            utilisation: self.utilisation(),
            jitter_load: scaled_floor(jitter.as_ns(), self.utilisation()).min(BOUND_LIMIT),
            zero_periods: 0,
        }
    }
}

impl Load {
    /// The load of one interferer (nothing when it costs nothing).
    pub fn of<A: Activations>(other: &A) -> Load {
        Share::of(other.activation_cost(), other.period()).load(other.jitter())
    }

    /// Both loads together.
    pub fn plus(self, other: Load) -> Load {
        Load {
            utilisation: self.utilisation.saturating_add(other.utilisation),
            jitter_load: self.jitter_load.saturating_add(other.jitter_load),
            zero_periods: self.zero_periods.saturating_add(other.zero_periods),
        }
    }

    /// This load without `part` (which must be one of its terms).
    pub fn minus(self, part: Load) -> Load {
        Load {
            utilisation: self.utilisation.saturating_sub(part.utilisation),
            jitter_load: self.jitter_load.saturating_sub(part.jitter_load),
            zero_periods: self.zero_periods.saturating_sub(part.zero_periods),
        }
    }

    /// The load of `others` except `exclude`.
    pub fn sum<A: Activations>(others: &[A], exclude: Option<usize>) -> Load {
        others
            .iter()
            .enumerate()
            .filter(|(k, _)| Some(*k) != exclude)
            .fold(Load::default(), |load, (_, other)| {
                load.plus(Load::of(other))
            })
    }
}

/// `⌊c/t · 2^UTIL_BITS⌋` rounded down, capped at [`UTIL_ONE`] (one such interferer already overloads any level
/// with work of its own). `t > 0`.
fn utilisation_floor(c: u64, t: u64) -> u64 {
    if c >= t {
        return UTIL_ONE;
    }
    if t >> 32 == 0 {
        // c < t < 2^32: exactly ⌊c · 2^UTIL_BITS / t⌋, by 32-bit divisions.
        return shifted_quotient(c, t);
    }
    // c < t: shift both until c·2^UTIL_BITS fits; c rounds down and t up, so the quotient stays at most c/t.
    let shift = (64 - c.leading_zeros()).saturating_sub(64 - UTIL_BITS);
    let c_scaled = (c >> shift) << UTIL_BITS;
    let t_scaled = if shift == 0 {
        t
    } else {
        ceil_div(t, 1 << shift)
    };
    c_scaled / t_scaled.max(1)
}

/// `⌊n · 2^UTIL_BITS / d⌋` for `n < 2^(64 − UTIL_BITS)` and `d > 0`. When both fit in 32 bits this is a long
/// division by the Cortex-M3's 32-bit hardware divide, a few bits per step (as many as `d` leaves free in a 32-bit
/// remainder), instead of the 64-bit software division (≈ 150 instructions a call on the chip): the same quotient.
fn shifted_quotient(n: u64, d: u64) -> u64 {
    if let (Ok(n32), Ok(d32)) = (u32::try_from(n), u32::try_from(d)) {
        // A remainder is below `d`, so it can be shifted left by `d`'s leading zeros without overflow.
        let step = d32.leading_zeros();
        if d32 != 0 && step > 0 {
            let high = u64::from(n32 / d32);
            let mut r = n32 % d32;
            // The low UTIL_BITS bits of the quotient, in 32 bits (no 64-bit shifts in the loop).
            let mut low = 0u32;
            let mut left = UTIL_BITS;
            while left > 0 {
                let s = step.min(left);
                let x = r << s;
                low = (low << s) | (x / d32);
                r = x % d32;
                left -= s;
            }
            return (high << UTIL_BITS) | u64::from(low);
        }
    }
    n.checked_shl(UTIL_BITS)
        .and_then(|x| x.checked_div(d))
        .unwrap_or(u64::MAX)
}

/// `⌊x · u / 2^UTIL_BITS⌋` for a fixed-point utilisation `u ≤ UTIL_ONE`, or 0 when `x` is too large for the
/// product (leaving a term out only lowers a start bound).
fn scaled_floor(x: u64, u: u64) -> u64 {
    x.checked_mul(u).map_or(0, |p| p >> UTIL_BITS)
}

/// Worst-case response time of `subject`, delayed by every stream in `others` except `exclude`.
///
/// `scratch` should hold at least `others.len()` counters; with fewer, every iteration divides once per
/// interferer instead (same result, slower).
pub fn response_time<A: Activations>(
    subject: &Subject,
    others: &[A],
    exclude: Option<usize>,
    discipline: Discipline,
    limits: &Limits,
    scratch: &mut [Counter],
) -> Result<Response, AnalysisError> {
    let load = Load::sum(others, exclude);
    response_time_loaded(subject, others, exclude, load, discipline, limits, scratch)
}

/// [`response_time`] with the load of `others` except `exclude` already summed ([`Load::sum`] of the same
/// interferers; a caller analysing every member of a set sums each priority level once).
pub fn response_time_loaded<A: Activations>(
    subject: &Subject,
    others: &[A],
    exclude: Option<usize>,
    load: Load,
    discipline: Discipline,
    limits: &Limits,
    scratch: &mut [Counter],
) -> Result<Response, AnalysisError> {
    let t_own = subject.period.as_ns();
    if t_own == 0 || load.zero_periods > 0 {
        return Err(AnalysisError::Overload);
    }
    let per = u64::from(subject.instances_per_activation.max(1));
    let own_activation = mul(subject.cost.as_ns(), per)?;
    let u_own = match subject.known_utilisation {
        Some(u) => u,
        None if own_activation == 0 => 0,
        None => utilisation_floor(own_activation, t_own),
    };
    // Rounded down, so above 100 % is a real overload; a level loaded to within rounding of 100 % stops at the
    // horizon instead.
    if load.utilisation.saturating_add(u_own) > UTIL_ONE
        || (load.utilisation >= UTIL_ONE && own_activation > 0)
    {
        return Err(AnalysisError::Overload);
    }
    let loads = Loads {
        u_hp: load.utilisation,
        u_own,
        jitter_load: load.jitter_load,
    };
    let mut window = Window::new(others, exclude, scratch, limits);
    match discipline {
        Discipline::Preemptive => preemptive(subject, &mut window, &loads),
        Discipline::NonPreemptive { bit_time } => {
            non_preemptive(subject, per, bit_time.as_ns(), &mut window, &loads)
        }
    }
}

struct Loads {
    u_hp: u64,
    u_own: u64,
    jitter_load: u64,
}

/// The interfering streams and their counters.
struct Window<'a, 'b, A> {
    others: &'a [A],
    exclude: Option<usize>,
    /// The counters (valid in `heap[..len]`), or empty when the scratch is too small to hold all.
    heap: &'b mut [Counter],
    len: usize,
    /// Σ count·C over the heap.
    sum: u64,
    /// The window the counters were last brought to: every counter's next activation is at or beyond it, so a
    /// window that has not grown past it changes no count (the first evaluation after [`Window::start`], the next
    /// instance's first evaluation) and needs no pass over the counters.
    reached: u32,
    horizon: u64,
    /// Evaluations of the interference sum allowed ([`Limits::iterations`]).
    max_iterations: u64,
    /// Evaluations of the interference sum so far.
    iterations: u64,
}

impl<'a, 'b, A: Activations> Window<'a, 'b, A> {
    fn new(
        others: &'a [A],
        exclude: Option<usize>,
        scratch: &'b mut [Counter],
        limits: &Limits,
    ) -> Self {
        // Without room for every interferer, fall back to dividing once per interferer and iteration.
        let heap = if scratch.len() >= others.len() {
            scratch
        } else {
            &mut []
        };
        Window {
            others,
            exclude,
            heap,
            len: 0,
            sum: 0,
            reached: 0,
            horizon: limits.horizon.as_ns(),
            max_iterations: limits.iterations.min(MAX_ITERATIONS),
            iterations: 0,
        }
    }

    fn usable(&self, k: usize, other: &A) -> Option<(u64, u64, u64)> {
        let (c, t) = (other.activation_cost().as_ns(), other.period().as_ns());
        (Some(k) != self.exclude && c != 0 && t != 0).then_some((c, t, other.jitter().as_ns()))
    }

    /// Counts every interferer's activations before `x` from scratch: `⌈(x + J_k)/T_k⌉`.
    fn start(&mut self, x: u64) -> Result<(), AnalysisError> {
        self.len = 0;
        self.sum = 0;
        if self.heap.is_empty() {
            return Ok(());
        }
        let Ok(x32) = u32::try_from(x) else {
            // A window beyond 32 bits: summed by dividing (`demand`).
            self.heap = &mut [];
            return Ok(());
        };
        self.reached = x32;
        for (k, other) in self.others.iter().enumerate() {
            let Some((c, t, j)) = self.usable(k, other) else {
                continue;
            };
            let counted = Counter::at(x32, c, t, j);
            let (Some(counter), Some(slot)) = (counted, self.heap.get_mut(self.len)) else {
                // Outside 32 bits: this window is summed by dividing.
                self.heap = &mut [];
                self.len = 0;
                return Ok(());
            };
            *slot = counter;
            self.len += 1;
            self.sum = add(self.sum, u64::from(counter.count) * u64::from(counter.cost))?;
        }
        Ok(())
    }

    /// Σ_k ⌈(x + J_k)/T_k⌉·C_k. With counters, `x` must not decrease between calls after [`Window::start`]:
    /// a counter is only touched (one division at most) when the window passed its next activation.
    fn demand(&mut self, x: u64) -> Result<u64, AnalysisError> {
        self.iterations += 1;
        if self.iterations > self.max_iterations {
            return Err(AnalysisError::IterationLimit);
        }
        if let Ok(x32) = u32::try_from(x) {
            if !self.heap.is_empty() {
                if let Some(sum) = self.count_to(x32) {
                    return Ok(sum);
                }
                // A count outside 32 bits: the rest of this window is summed by dividing.
                self.heap = &mut [];
            }
        } else {
            self.heap = &mut [];
        }
        let mut sum = 0u64;
        for (k, other) in self.others.iter().enumerate() {
            if let Some((c, t, j)) = self.usable(k, other) {
                sum = add(sum, mul(ceil_div(add(x, j)?, t), c)?)?;
            }
        }
        Ok(sum)
    }

    /// The counters brought to `x` (`None`: a count left 32 bits).
    fn count_to(&mut self, x: u32) -> Option<u64> {
        if x <= self.reached {
            return Some(self.sum);
        }
        let counters = self.heap.get_mut(..self.len).unwrap_or(&mut []);
        let mut sum = self.sum;
        for counter in counters.iter_mut() {
            if counter.next >= x {
                continue;
            }
            let (c, t, j) = (counter.cost, counter.period, counter.jitter);
            // The window passed one activation (the common case: `next < x ≤ next + T`): the count at `x` is
            // one more, no division. Otherwise jump straight to the count at `x` (one division however many
            // activations the window grew by).
            if x - counter.next <= t && counter.next != 0 {
                // One more activation: the next one a period later (`next` is `count·T − J` itself, not
                // clamped at 0; saturating at `u32::MAX`, which no 32-bit window passes).
                counter.count = counter.count.checked_add(1)?;
                counter.next = counter.next.saturating_add(t);
                sum = sum.checked_add(u64::from(c))?;
            } else {
                let (mut count, mut next) = count_at(x, t, j)?;
                if count <= counter.count {
                    count = counter.count.checked_add(1)?;
                    next = next_activation(count, t, j);
                }
                sum = sum.checked_add(u64::from(count - counter.count) * u64::from(c))?;
                counter.count = count;
                counter.next = next;
            }
        }
        self.sum = sum;
        self.reached = x;
        Some(sum)
    }
}

/// An interferer's activations before `x`, `count = ⌈(x + J)/T⌉`, and its next activation `count·T − J` (saturated
/// at `u32::MAX`, which no 32-bit window passes), from one division: with `q, r` the quotient and remainder of
/// `x + J − 1` by `T`, `count = q + 1` and `count·T − J = x + (T − 1 − r)` — no 64-bit multiply. `None` for a zero `T`
/// or `x + J` beyond 32 bits.
#[inline(always)]
fn count_at(x: u32, t: u32, j: u32) -> Option<(u32, u32)> {
    let a = x.checked_add(j)?;
    if a == 0 {
        return Some((0, 0));
    }
    let q = (a - 1).checked_div(t)?;
    let r = (a - 1) - q * t;
    Some((q + 1, x.saturating_add(t - 1 - r)))
}

/// `count·T − J`, saturated at `u32::MAX` (no 32-bit window passes it).
#[inline(always)]
fn next_activation(count: u32, t: u32, j: u32) -> u32 {
    let next = (u64::from(count) * u64::from(t)).saturating_sub(u64::from(j));
    u32::try_from(next).unwrap_or(u32::MAX)
}

/// A start for the fixed point of `x = constant + Σ ⌈(x + shift + J_k)/T_k⌉·C_k` (plus the subject's own
/// activations when `with_own`) that is at most its least solution: since `⌈y⌉ ≥ y`, every solution satisfies
/// `x·(1 − U) ≥ constant + Σ (shift + J_k)·U_k`. `floor` is a start known to be safe anyway.
fn lower_bound(
    constant: u64,
    floor: u64,
    shift: u64,
    loads: &Loads,
    with_own: bool,
    own_jitter: u64,
) -> u64 {
    let u = if with_own {
        loads.u_hp.saturating_add(loads.u_own)
    } else {
        loads.u_hp
    };
    let slack = UTIL_ONE.saturating_sub(u);
    if slack == 0 || slack < UTIL_ONE / MIN_SLACK_FOR_BOUND {
        return floor;
    }
    // Every term rounded down and `1 − U` rounded up: the quotient stays at or below the least solution.
    let mut numerator = Some(constant)
        .and_then(|n| n.checked_add(loads.jitter_load))
        .and_then(|n| n.checked_add(scaled_floor(shift.min(BOUND_LIMIT), loads.u_hp)));
    if with_own {
        numerator = numerator
            .and_then(|n| n.checked_add(scaled_floor(own_jitter.min(BOUND_LIMIT), loads.u_own)));
    }
    match numerator {
        Some(n) if n < BOUND_LIMIT => shifted_quotient(n, slack).max(floor),
        _ => floor,
    }
}

fn preemptive<A: Activations>(
    subject: &Subject,
    window: &mut Window<'_, '_, A>,
    loads: &Loads,
) -> Result<Response, AnalysisError> {
    let c = subject.cost.as_ns();
    let b = subject.blocking.as_ns();
    let t = subject.period.as_ns();
    let j = subject.jitter.as_ns();
    let first = add(b, c)?;
    let mut w =
        lower_bound(first, first, 0, loads, false, 0).max(subject.known_first_window.as_ns());
    window.start(w)?;
    let mut worst: Option<Response> = None;
    let mut q: u64 = 0;
    loop {
        let own = add(b, mul(q + 1, c)?)?;
        let interference = loop {
            let interference = window.demand(w)?;
            let demand = add(own, interference)?;
            if demand <= w {
                break interference;
            }
            w = demand;
            if w > window.horizon {
                return Err(AnalysisError::BeyondHorizon);
            }
        };
        let r = add(w, j)?.saturating_sub(mul(q, t)?);
        if worst.is_none_or(|best| r > best.wcrt.as_ns()) {
            worst = Some(Response {
                wcrt: Time::from_ns(r),
                worst_instance: q,
                instances: 0,
                busy_window: Time::ZERO,
                interference: Time::from_ns(interference),
                first_window: worst.map_or(Time::from_ns(w), |best| best.first_window),
                iterations: 0,
            });
        }
        if add(w, j)? <= mul(q + 1, t)? {
            break;
        }
        q += 1;
        if q >= MAX_INSTANCES {
            return Err(AnalysisError::BeyondHorizon);
        }
    }
    let mut response = worst.ok_or(AnalysisError::BeyondHorizon)?;
    response.instances = q + 1;
    response.busy_window = Time::from_ns(w);
    response.iterations = window.iterations;
    Ok(response)
}

fn non_preemptive<A: Activations>(
    subject: &Subject,
    per: u64,
    tau: u64,
    window: &mut Window<'_, '_, A>,
    loads: &Loads,
) -> Result<Response, AnalysisError> {
    let c = subject.cost.as_ns();
    let b = subject.blocking.as_ns();
    let t = subject.period.as_ns();
    let j = subject.jitter.as_ns();
    let own_activation = mul(c, per)?;

    // The level busy period, own activations included.
    let mut busy = lower_bound(b, add(b, own_activation)?, 0, loads, true, j)
        .max(subject.known_busy_period.as_ns())
        .max(1);
    window.start(busy)?;
    loop {
        let own = mul(ceil_div(add(busy, j)?, t), own_activation)?;
        let demand = add(add(b, own)?, window.demand(busy)?)?;
        if demand <= busy {
            break;
        }
        busy = demand;
        if busy > window.horizon {
            return Err(AnalysisError::BeyondHorizon);
        }
    }
    let activations = ceil_div(add(busy, j)?, t).max(1);
    let instances = mul(activations, per)?;
    if instances > MAX_INSTANCES {
        return Err(AnalysisError::BeyondHorizon);
    }

    let mut w = lower_bound(b, b, tau, loads, false, 0).max(subject.known_first_window.as_ns());
    window.start(add(w, tau)?)?;
    let mut worst: Option<Response> = None;
    // The instances analysed: the first (its window is the first window other messages start from), then the
    // last of each activation. Within an activation the queuing windows grow with the instance (each is the least
    // fixed point of `w = B + q·C + I(w + τ)`, increasing in `q`) and the activation's release is the same, so
    // its last instance has its worst response: the others cannot be the worst and are skipped (the window of
    // the last one is reached from the first one's, as the windows only grow). One instance per activation when
    // a sample is one frame.
    let mut q = 0;
    while q < instances {
        let own = add(b, mul(q, c)?)?;
        let interference = loop {
            let interference = window.demand(add(w, tau)?)?;
            let demand = add(own, interference)?;
            if demand <= w {
                break interference;
            }
            w = demand;
            if w > window.horizon {
                return Err(AnalysisError::BeyondHorizon);
            }
        };
        // Frames per activation are almost always 1: no 64-bit division then.
        let activation = if per == 1 { q } else { q / per };
        let r = add(add(w, c)?, j)?.saturating_sub(mul(activation, t)?);
        if worst.is_none_or(|best| r > best.wcrt.as_ns()) {
            worst = Some(Response {
                wcrt: Time::from_ns(r),
                worst_instance: q,
                instances,
                busy_window: Time::from_ns(busy),
                interference: Time::from_ns(interference),
                first_window: worst.map_or(Time::from_ns(w), |best| best.first_window),
                iterations: 0,
            });
        }
        // The next activation's last instance (or this one's, after its first).
        let last = add(mul(activation, per)?, per - 1)?;
        q = if q < last { last } else { add(q, per)? };
    }
    let mut response = worst.ok_or(AnalysisError::BeyondHorizon)?;
    response.iterations = window.iterations;
    Ok(response)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Clone, Copy, Debug)]
    struct Stream(u64, u64, u64);

    impl Activations for Stream {
        fn activation_cost(&self) -> Time {
            Time::from_ns(self.0)
        }
        fn period(&self) -> Time {
            Time::from_ns(self.1)
        }
        fn jitter(&self) -> Time {
            Time::from_ns(self.2)
        }
    }

    fn subject(c: u64, t: u64) -> Subject {
        Subject::new(
            Time::from_ns(c),
            1,
            Time::from_ns(t),
            Time::ZERO,
            Time::ZERO,
        )
    }

    /// The preemptive analysis of `s` delayed by `others` under the default limits, summed by division.
    fn analyse_preemptive(s: &Subject, others: &[Stream]) -> Result<Response, AnalysisError> {
        response_time(
            s,
            others,
            None,
            Discipline::Preemptive,
            &Limits::default(),
            &mut [],
        )
    }

    /// The analysis with a counter per interferer and by division alone, which must agree; their answer.
    fn counted_as_divided(
        s: &Subject,
        others: &[Stream],
        discipline: Discipline,
        limits: &Limits,
    ) -> Result<Response, AnalysisError> {
        let mut scratch = vec![Counter::default(); others.len()];
        let with = response_time(s, others, None, discipline, limits, &mut scratch);
        let without = response_time(s, others, None, discipline, limits, &mut []);
        assert_eq!(with, without, "{others:?} {discipline:?}");
        with
    }

    #[test]
    fn the_long_division_is_the_64_bit_one() {
        let mut x = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        let edges = [
            1,
            2,
            3,
            255,
            256,
            65_535,
            1 << 24,
            (1 << 24) + 1,
            u32::MAX as u64 - 1,
            u32::MAX as u64,
        ];
        for _ in 0..200_000 {
            let n = next() >> (next() % 64).max(UTIL_BITS as u64);
            let d = (next() >> (next() % 64)).max(1);
            let d = if next() % 8 == 0 {
                edges[(next() % edges.len() as u64) as usize]
            } else {
                d
            };
            assert_eq!(shifted_quotient(n, d), (n << UTIL_BITS) / d, "{n} {d}");
        }
        for &n in &edges {
            for &d in &edges {
                assert_eq!(shifted_quotient(n, d), (n << UTIL_BITS) / d, "{n} {d}");
            }
        }
    }

    /// A xorshift generator from `seed`: each call a number below its argument (below 1 for 0).
    fn below(seed: u64) -> impl FnMut(u64) -> u64 {
        let mut x = seed;
        move |limit: u64| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x % limit.max(1)
        }
    }

    /// The exact preemptive analysis of a subject (cost `c`, blocking `b`, period `t`, jitter `j`, ns) delayed by
    /// `others`, with no horizon or iteration limit in the way: what the random tests below compare with.
    fn exact_preemptive(
        c: u64,
        b: u64,
        t: u64,
        j: u64,
        others: &[Stream],
    ) -> Result<Response, AnalysisError> {
        let subject = Subject::new(
            Time::from_ns(c),
            1,
            Time::from_ns(t),
            Time::from_ns(j),
            Time::from_ns(b),
        );
        let limits = Limits {
            horizon: Time::from_ns(u64::MAX / 4),
            iterations: MAX_ITERATIONS,
        };
        let mut scratch = [Counter::default(); 16];
        response_time(
            &subject,
            others,
            None,
            Discipline::Preemptive,
            &limits,
            &mut scratch,
        )
    }

    /// The closed-form bound is never below the exact analysis: on 20 000 random sets (utilisations up to 100 %,
    /// jitters, blocking, periods across 32 bits) the least fixed point is at most `w̄`, and when `w̄ + J` fits in
    /// the period the exact worst-case response is at most `w̄ + J`. With no interferer it is `b + c`, up to one unit
    /// of rounding.
    #[test]
    fn the_linear_bound_is_above_the_exact_response() {
        let mut next = below(0x9e37_79b9_7f4a_7c15);
        let (mut checked, mut single) = (0, 0);
        for _ in 0..20_000 {
            let scale = [1_000, 100_000, 10_000_000, 5_000_000_000][next(4) as usize];
            let others: Vec<Stream> = (0..next(8))
                .map(|_| {
                    let t = 1 + next(scale);
                    Stream(next(t / 3 + 1), t, next(t))
                })
                .collect();
            let t = 1 + next(scale * 4);
            let (c, b, j) = (1 + next(t / 4 + 1), next(t / 8 + 1), next(t / 2 + 1));
            let terms = others.iter().fold(LinearTerms::default(), |sum, o| {
                let load =
                    Share::of(Time::from_ns(o.0), Time::from_ns(o.1)).load(Time::from_ns(o.2));
                sum.plus(LinearTerms::of(load, o.0, o.1, o.2))
            });
            let Some(bound) = linear_bound(c, b, terms) else {
                continue;
            };
            let Ok(exact) = exact_preemptive(c, b, t, j, &others) else {
                continue;
            };
            checked += 1;
            assert!(
                exact.first_window.as_ns() <= bound,
                "window {exact:?} above {bound}: c {c} b {b} t {t} j {j} {others:?}"
            );
            if bound + j <= t {
                single += 1;
                assert!(
                    exact.wcrt.as_ns() <= bound + j,
                    "response {exact:?} above {bound} + {j}: c {c} b {b} t {t} {others:?}"
                );
            }
        }
        assert!(checked > 5_000 && single > 1_000, "{checked} {single}");
        // Tight where it must be: no interferer, the bound is b + c exactly.
        // No interferer: b + c, up to the rounding of one unit.
        assert!(matches!(
            linear_bound(7, 3, LinearTerms::default()),
            Some(10 | 11)
        ));
        // 100 % of interferers: no bound; a zero period or an interferer at 100 %: no terms.
        for (c, t) in [(5, 0), (5, 5)] {
            let load = Share::of(Time::from_ns(c), Time::from_ns(t)).load(Time::ZERO);
            let unusable = LinearTerms::of(load, c, t, 0);
            assert_eq!(linear_bound(1, 0, unusable), None, "{c} every {t}");
        }
        assert_eq!(
            linear_bound(
                1,
                0,
                LinearTerms {
                    cost: 1,
                    utilisation: UTIL_ONE,
                    jitter_load: 0
                }
            ),
            None
        );
    }

    /// When `w = B + C + Σ C_k` leaves every interferer's next activation, and the subject's own, outside the
    /// window (`w + J_k ≤ T_k`), the exact analysis's first window is `w` and its response `w + J`: the admission
    /// check takes these numbers without a fixed point. Checked on 20 000 random sets that meet the condition.
    #[test]
    fn a_window_that_holds_one_activation_of_each_is_their_sum() {
        let mut next = below(0x2545_f491_4f6c_dd1d);
        let mut checked = 0;
        while checked < 20_000 {
            let scale = [1_000, 100_000, 10_000_000][next(3) as usize];
            let others: Vec<Stream> = (0..next(10))
                .map(|_| {
                    let t = 1 + next(scale);
                    Stream(next(t / 8 + 1), t, next(t / 4 + 1))
                })
                .collect();
            let t = 1 + next(scale);
            let (c, b, j) = (1 + next(t / 8 + 1), next(t / 16 + 1), next(t / 4 + 1));
            let w = b + c + others.iter().map(|o| o.0).sum::<u64>();
            let gap = others
                .iter()
                .filter(|o| o.0 > 0)
                .map(|o| o.1.saturating_sub(o.2))
                .chain([t.saturating_sub(j)])
                .min()
                .unwrap_or(u64::MAX);
            let load = Load::sum(&others, None);
            let u_own = Share::of(Time::from_ns(c), Time::from_ns(t)).utilisation();
            if w > gap || load.utilisation + u_own > UTIL_ONE {
                continue;
            }
            checked += 1;
            let exact = exact_preemptive(c, b, t, j, &others)
                .unwrap_or_else(|e| panic!("{e:?}: c {c} b {b} t {t} j {j} {others:?}"));
            assert_eq!(
                (
                    exact.first_window.as_ns(),
                    exact.wcrt.as_ns(),
                    exact.busy_window.as_ns()
                ),
                (w, w + j, w),
                "c {c} b {b} t {t} j {j} {others:?}"
            );
        }
    }

    #[test]
    fn a_share_is_the_load_it_stands_for() {
        for (c, t, j) in [
            (0, 0, 5),
            (3, 0, 1),
            (3, 7, 2),
            (700_000, 900_000, 12_000),
            (5, 3, 0),
            (1, 1 << 40, 9),
        ] {
            let stream = Stream(c, t, j);
            assert_eq!(
                Share::of(Time::from_ns(c), Time::from_ns(t)).load(Time::from_ns(j)),
                Load::of(&stream)
            );
        }
    }

    #[test]
    fn counters_and_divisions_agree() {
        // The same analysis with and without scratch must give the same answer.
        let others = [Stream(3, 7, 2), Stream(3, 12, 0), Stream(1, 5, 4)];
        let with = counted_as_divided(
            &subject(5, 80),
            &others,
            Discipline::Preemptive,
            &Limits::default(),
        );
        assert!(with.is_ok());
    }

    #[test]
    fn windows_beyond_32_bits_are_counted_as_below() {
        // Counters keep 32-bit nanoseconds; a window that grows past 4.29 s, or an interferer whose period,
        // cost or jitter does not fit, is summed by dividing. Either way the answer is the division's, in both
        // disciplines: a heavily loaded level (windows of seconds) and a period beyond 32 bits.
        let second = 1_000_000_000u64;
        let sets: [(&[Stream], Subject); 3] = [
            (
                &[
                    Stream(700_000_000, second, 0),
                    Stream(500_000_000, 2 * second, 7),
                ],
                subject(300_000_000, 60 * second),
            ),
            (
                &[Stream(3, 7, 2), Stream(1_000, 5 * second, 4 * second)],
                subject(5, 80),
            ),
            (
                &[Stream(400_000_000, second, 5_000_000_000), Stream(2, 9, 1)],
                subject(1_000_000, 10 * second),
            ),
        ];
        for (others, s) in sets {
            for discipline in [
                Discipline::Preemptive,
                Discipline::NonPreemptive {
                    bit_time: Time::from_ns(1),
                },
            ] {
                let limits = Limits {
                    horizon: Time::from_ns(1_000 * second),
                    ..Limits::default()
                };
                counted_as_divided(&s, others, discipline, &limits).ok();
            }
        }
        // The first set's window does pass 2^32 ns.
        let (others, s) = sets[0];
        let r = response_time(
            &s,
            others,
            None,
            Discipline::Preemptive,
            &Limits::default(),
            &mut [Counter::default(); 2],
        );
        assert!(
            r.is_ok_and(|r| r.busy_window.as_ns() > u64::from(u32::MAX)),
            "{r:?}"
        );
    }

    #[test]
    fn counters_jump_over_several_activations_at_once() {
        // A later job adds 50 to the window at once: the interferer (T 10, J 25) gains five activations in one
        // step, all of which the counter must take (w(1) = 100 + ⌈(w + 25)/10⌉ → 114).
        let others = [Stream(1, 10, 25)];
        let s = Subject::new(
            Time::from_ns(50),
            1,
            Time::from_ns(60),
            Time::from_ns(10),
            Time::ZERO,
        );
        let with = counted_as_divided(&s, &others, Discipline::Preemptive, &Limits::default());
        assert_eq!(with.map(|r| r.instances > 1), Ok(true));
    }

    #[test]
    fn overload_is_reported_not_looped_on() {
        let others = [Stream(6, 10, 0)];
        let s = subject(5, 10);
        assert_eq!(
            analyse_preemptive(&s, &others),
            Err(AnalysisError::Overload)
        );
        let r = response_time(
            &s,
            &others,
            None,
            Discipline::NonPreemptive {
                bit_time: Time::from_ns(1),
            },
            &Limits::default(),
            &mut [],
        );
        assert_eq!(r, Err(AnalysisError::Overload));
    }

    #[test]
    fn full_utilisation_stops_at_the_horizon() {
        // U = 1 exactly with co-prime periods: the window only closes at the hyperperiod, beyond the horizon.
        let others = [Stream(500, 1000, 0)];
        let s = subject(501, 1002);
        let limits = Limits {
            horizon: Time::from_ns(100_000),
            ..Limits::default()
        };
        let r = response_time(&s, &others, None, Discipline::Preemptive, &limits, &mut []);
        assert!(
            matches!(
                r,
                Err(AnalysisError::BeyondHorizon) | Err(AnalysisError::Overload)
            ),
            "{r:?}"
        );
    }

    #[test]
    fn saturation_is_an_error_never_a_bound() {
        // Issue 12: WCET 1e300 µs, period 1e17 µs. Saturating arithmetic made the window "close" at u64::MAX and
        // the response equal to the (saturated) deadline, i.e. "ok". Every such case must now be an error.
        let huge = Time::from_us_up(1e300);
        let period = Time::from_us_down(1e17);
        let s = Subject::new(huge, 1, period, Time::ZERO, Time::from_ns(1));
        for discipline in [
            Discipline::Preemptive,
            Discipline::NonPreemptive {
                bit_time: Time::from_ns(1000),
            },
        ] {
            let r = response_time(
                &s,
                &[Stream(1, 1_000_000, 0)],
                None,
                discipline,
                &Limits {
                    horizon: Time::MAX,
                    ..Limits::default()
                },
                &mut [Counter::default(); 1],
            );
            assert!(
                r.as_ref().err().is_some_and(|e| e.is_unbounded()),
                "{discipline:?}: {r:?}"
            );
        }
        // A jitter near the top of the range overflows the activation count.
        let s = Subject::new(
            Time::from_ns(1),
            1,
            Time::from_ns(100),
            Time::ZERO,
            Time::ZERO,
        );
        let r = response_time(
            &s,
            &[Stream(1, 100, u64::MAX - 1)],
            None,
            Discipline::Preemptive,
            &Limits {
                horizon: Time::MAX,
                ..Limits::default()
            },
            &mut [Counter::default(); 1],
        );
        assert_eq!(r, Err(AnalysisError::Overflow));
    }

    #[test]
    fn iterations_are_counted() {
        let others = [Stream(3, 7, 2), Stream(3, 12, 0), Stream(1, 5, 4)];
        let r = analyse_preemptive(&subject(5, 80), &others);
        assert!(r.is_ok_and(|r| r.iterations >= 2), "{r:?}");
    }

    #[test]
    fn a_zero_period_interferer_is_overload() {
        let others = [Stream(1, 0, 0)];
        assert_eq!(
            analyse_preemptive(&subject(1, 10), &others),
            Err(AnalysisError::Overload)
        );
    }
}
