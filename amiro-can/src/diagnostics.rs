//! Board health on the bus: the pages of a diagnostics sample and of an admission verdict.
//!
//! Every board owns one diagnostics topic (`0x1A` DiWheelDrive, `0x1B` PowerManagement, `0x1C` LightRing). It is
//! a sensor topic like any other: stop / publish / once through the normal sensor commands, published at the
//! priority of the command. Every frame is DLC 8 and byte 0 names its page (as the proximity ring's byte 0 names
//! its sensor); bytes 1–7 carry the page's fields, little-endian:
//!
//! | Page | Name | Fields |
//! |------|------|--------|
//! | 0 | status | 1–4 uptime u32 (s); 5 reset cause flags; 6 status flags; 7 sensor faults u8 |
//! | 1 | commands | 1–3 accepted u24; 4–6 rejected (malformed, every reason) u24; 7 number of reasons the board counts |
//! | 2 | rejections | 1 first reason index; 2–7 three u16 counters, reasons `first`, `first+1`, `first+2` |
//! | 3 | admission and receive | 1–2 admission refusals u16; 3–4 accepted with warning u16; 5–6 receive drops u16 (a lower bound); 7 receive FIFO overruns u8 |
//! | 4 | transmit and bus | 1–3 transmit-queue drops u24; 4–5 displacements u16; 6 error-passive episodes u8; 7 bus-off episodes u8 |
//! | 5 | deadlines | 1–7: four 14-bit deadline-miss counters, urgent (bits 0–13) … low (bits 42–55) |
//! | 0x80 | verdict | the admission verdict's request: see [`VerdictRequest`] |
//! | 0x81 | verdict bound | the admission verdict's bound: see [`VerdictBound`] |
//!
//! Page 2's reasons `0..REJECT_REASONS` are why a command was rejected as malformed, in [`DecodeError::KINDS`]
//! order; reasons `REJECT_REASONS..COUNTED_REASONS` are why the admission check refused — or, under
//! accept-and-warn, warned about — a request, in [`RefusalReason::ALL`] order; [`reason_name`] names any index.
//!
//! One sample is pages 0–5 in that order ([`PAGES_PER_SAMPLE`] frames). Counters saturate at their width's
//! maximum (a [`Count`]). The per-reason counters do not fit one sample: each sample carries three of them, and
//! the board moves the window on by three per sample ([`Diagnostics::next_window`]), so a receiver has every
//! reason after `ceil(COUNTED_REASONS / 3)` samples; page 1 carries the malformed total and page 3 the admission
//! totals in every sample.
//!
//! The verdict pages are not part of a sample: a board sends the pair (0x80, then 0x81, same identifier) when
//! its admission check refuses a publish or re-prioritisation request, or accepts one with a warning, at the
//! priority of that request.

use core::fmt;

use crate::command::{SampleTime, TimeUnit};
use crate::error::DecodeError;
use crate::frame::Frame;
use crate::id::{CanId, Kind, Priority};
use crate::payload::SensorData;
use crate::topic::{Board, Topic};

/// Frames in one diagnostics sample: pages 0 to 5.
pub const PAGES_PER_SAMPLE: u8 = 6;
/// Page byte of an admission verdict's first frame ([`VerdictRequest`]).
pub const VERDICT_PAGE: u8 = 0x80;
/// The requested-unit value (byte 4, bits 0–1, of [`VERDICT_PAGE`]) that marks a one-shot request: its sample
/// time is the interval in ms the board analysed it at.
pub const ONE_SHOT_UNIT: u8 = 3;
/// Page byte of an admission verdict's second frame ([`VerdictBound`]).
pub const VERDICT_BOUND_PAGE: u8 = 0x81;
/// Rejection counters carried by one sample (page 2).
pub const REJECTIONS_PER_SAMPLE: usize = 3;
/// Rejection reasons a board counts: one per [`DecodeError::kind_index`].
pub const REJECT_REASONS: usize = DecodeError::KINDS.len();
/// Admission refusal reasons a board counts: one per [`RefusalReason`].
pub const REFUSAL_REASONS: usize = RefusalReason::ALL.len();
/// Every reason page 2 carries: the rejection reasons, then the refusal reasons.
pub const COUNTED_REASONS: usize = REJECT_REASONS + REFUSAL_REASONS;

// Page 1 reports the number of reasons in one byte, page 2 the first index in one byte.
const _: () = assert!(COUNTED_REASONS <= u8::MAX as usize);

/// Why the admission check refused a request (or, under accept-and-warn, warned about one): the reasons a board
/// counts on page 2 after the rejection reasons (index `REJECT_REASONS + reason as usize`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RefusalReason {
    /// A task of a board would miss its deadline.
    TaskDeadline = 0,
    /// A frame would miss its bus deadline.
    MessageDeadline = 1,
    /// A frame would miss its end-to-end deadline (release on its board to the end of its transmission).
    EndToEndDeadline = 2,
    /// The board cannot hold the configuration: more publishers, tasks or streams than its tables have room for.
    Capacity = 3,
    /// The request's period is zero.
    ZeroPeriod = 4,
    /// The board's admission task already holds as many requests as its queue has room for (requests come faster
    /// than the check's analysed rate): refused unseen, answered with a verdict, and counted.
    Busy = 5,
    /// The check ran out of the fixed-point iterations a decision may take (a configuration loaded close to
    /// 100 %): refused without a verdict on its deadlines, which bounds the check's cost.
    Budget = 6,
}

impl RefusalReason {
    /// Every reason, in counter order.
    pub const ALL: [RefusalReason; 7] = [
        RefusalReason::TaskDeadline,
        RefusalReason::MessageDeadline,
        RefusalReason::EndToEndDeadline,
        RefusalReason::Capacity,
        RefusalReason::ZeroPeriod,
        RefusalReason::Busy,
        RefusalReason::Budget,
    ];

    /// A short, stable name: counter and log names.
    pub const fn name(self) -> &'static str {
        match self {
            RefusalReason::TaskDeadline => "admission-task-deadline",
            RefusalReason::MessageDeadline => "admission-message-deadline",
            RefusalReason::EndToEndDeadline => "admission-end-to-end-deadline",
            RefusalReason::Capacity => "admission-capacity",
            RefusalReason::ZeroPeriod => "admission-zero-period",
            RefusalReason::Busy => "admission-busy",
            RefusalReason::Budget => "admission-iteration-budget",
        }
    }

    /// Its index among the reasons page 2 carries.
    pub const fn counted_index(self) -> usize {
        REJECT_REASONS + self as usize
    }
}

/// The name of page 2's reason `index`: a [`DecodeError::KINDS`] name, a [`RefusalReason::name`], or `None`
/// past [`COUNTED_REASONS`].
pub fn reason_name(index: usize) -> Option<&'static str> {
    match index.checked_sub(REJECT_REASONS) {
        None => DecodeError::KINDS.get(index).copied(),
        Some(i) => RefusalReason::ALL.get(i).map(|r| r.name()),
    }
}

/// A counter as it travels on the bus: `BITS` wide, saturating at `2^BITS − 1` instead of wrapping.
///
/// The value is private so a `Count` always fits its field; [`Count::saturating`] builds one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, PartialOrd, Ord)]
pub struct Count<const BITS: u32>(u32);

impl<const BITS: u32> Count<BITS> {
    /// The largest value, which also means "this many or more".
    pub const MAX: u32 = if BITS >= 32 {
        u32::MAX
    } else {
        (1u32 << BITS) - 1
    };
    /// Zero.
    pub const ZERO: Self = Count(0);

    /// `value`, or [`Count::MAX`] if it does not fit.
    pub const fn saturating(value: u32) -> Self {
        Count(if value > Self::MAX { Self::MAX } else { value })
    }

    /// The value.
    pub const fn get(self) -> u32 {
        self.0
    }

    /// True when the counter stopped at its maximum (the true count may be higher).
    pub const fn is_saturated(self) -> bool {
        self.0 == Self::MAX
    }
}

impl<const BITS: u32> fmt::Display for Count<BITS> {
    /// `17`, or `65535+` when saturated.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.0)?;
        if self.is_saturated() {
            f.write_str("+")?;
        }
        Ok(())
    }
}

/// A byte of flags on the wire: the set operations and the `name+name` text every such type
/// shares. Each type then declares its flags and `NAMES` (bit 0 first) in its own `impl`.
macro_rules! flag_byte {
    ($(#[$doc:meta])* $name:ident, $example:literal) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
        pub struct $name(u8);

        impl $name {
            /// No flag set.
            pub const NONE: $name = $name(0);

            /// From the wire byte; every bit is kept as it is, unassigned ones too.
            pub const fn from_bits(bits: u8) -> $name {
                $name(bits)
            }

            /// The wire byte.
            pub const fn bits(self) -> u8 {
                self.0
            }

            /// This set with `other`'s flags added.
            #[must_use]
            pub const fn with(self, other: $name) -> $name {
                $name(self.0 | other.0)
            }

            /// Whether every flag of `other` is set.
            pub const fn contains(self, other: $name) -> bool {
                self.0 & other.0 == other.0
            }
        }

        impl fmt::Display for $name {
            #[doc = $example]
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write_flags(f, self.0, &Self::NAMES)
            }
        }
    };
}

flag_byte!(
    /// Why the board last reset, as flags (several can be set: the STM32's `RCC_CSR` latches them until cleared).
    ResetCause,
    "`pin+independent-watchdog`, or `none`."
);

impl ResetCause {
    /// Power-on or power-down reset (`PORRSTF`).
    pub const POWER_ON: ResetCause = ResetCause(1 << 0);
    /// The NRST pin (`PINRSTF`): a button, a debugger, or a module pulling SYS_WARMRST_N.
    pub const PIN: ResetCause = ResetCause(1 << 1);
    /// The independent watchdog expired (`IWDGRSTF`).
    pub const INDEPENDENT_WATCHDOG: ResetCause = ResetCause(1 << 2);
    /// The window watchdog (`WWDGRSTF`).
    pub const WINDOW_WATCHDOG: ResetCause = ResetCause(1 << 3);
    /// A software reset (`SFTRSTF`), e.g. a restart through the bootloader.
    pub const SOFTWARE: ResetCause = ResetCause(1 << 4);
    /// Low-power management reset (`LPWRRSTF`).
    pub const LOW_POWER: ResetCause = ResetCause(1 << 5);
    /// Brown-out (`BORRSTF`, STM32F4 only).
    pub const BROWN_OUT: ResetCause = ResetCause(1 << 6);
    /// The previous run ended in a panic or HardFault (recorded by the firmware's fault policy, not `RCC_CSR`).
    pub const FAULT: ResetCause = ResetCause(1 << 7);

    const NAMES: [&'static str; 8] = [
        "power-on",
        "pin",
        "independent-watchdog",
        "window-watchdog",
        "software",
        "low-power",
        "brown-out",
        "fault",
    ];
}

flag_byte!(
    /// The board's state now, as flags.
    StatusFlags,
    "`watchdog+accept-and-warn`, or `none`."
);

impl StatusFlags {
    /// The admission policy is accept-and-warn (clear: refuse, the default).
    pub const ACCEPT_AND_WARN: StatusFlags = StatusFlags(1 << 0);
    /// The CAN controller is error-passive now.
    pub const ERROR_PASSIVE: StatusFlags = StatusFlags(1 << 1);
    /// At least one sensor fails now (its samples are missing).
    pub const SENSOR_FAULT: StatusFlags = StatusFlags(1 << 2);
    /// The independent watchdog runs.
    pub const WATCHDOG: StatusFlags = StatusFlags(1 << 3);
    /// The board is shutting down (SYS_PD_N low or a shutdown command).
    pub const SHUTTING_DOWN: StatusFlags = StatusFlags(1 << 4);
    /// The board does not run on its crystal's PLL (a clock step failed at boot: internal
    /// oscillator, with or without the PLL, or the clock the bootloader left).
    pub const CLOCK_FALLBACK: StatusFlags = StatusFlags(1 << 5);

    const NAMES: [&'static str; 8] = [
        "accept-and-warn",
        "error-passive",
        "sensor-fault",
        "watchdog",
        "shutting-down",
        "clock-fallback",
        "bit6",
        "bit7",
    ];
}

fn write_flags(f: &mut fmt::Formatter<'_>, bits: u8, names: &[&str; 8]) -> fmt::Result {
    if bits == 0 {
        return f.write_str("none");
    }
    let mut first = true;
    for (i, name) in names.iter().enumerate() {
        if bits & (1 << i) != 0 {
            if !first {
                f.write_str("+")?;
            }
            f.write_str(name)?;
            first = false;
        }
    }
    Ok(())
}

/// What the admission check decided.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Verdict {
    /// The request was refused; nothing changed.
    Refused,
    /// The request was carried out (policy accept-and-warn) although it breaks the bound named.
    AcceptedWithWarning,
}

impl fmt::Display for Verdict {
    /// `refused` or `accepted with a warning`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Verdict::Refused => "refused",
            Verdict::AcceptedWithWarning => "accepted with a warning",
        })
    }
}

/// What kind of thing the request would make miss its deadline (the first frame of a verdict says which,
/// the second frame says which one).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ViolationKind {
    /// Not named (the check failed for a reason it cannot attribute).
    Unknown,
    /// A task of the board, by its index in the board's analysed task list.
    Task,
    /// A sensor-data frame on the bus, at this priority (the second frame names its topic byte).
    Message {
        /// The frame's priority bits.
        priority: Priority,
    },
}

/// The first frame of an admission verdict (page 0x80): the request and what the board decided.
///
/// ```text
/// byte 1    requested topic
/// bytes 2–3 requested sample time value, u16
/// byte 4    bits 0–1 requested unit (0 ms, 1 s, 2 µs; 3: a one-shot request, analysed as a sample every `value`
///           ms — the board's one-shot interval); bits 2–3 requested priority; bit 4 verdict (0 refused,
///           1 accepted with warning); bits 5–7 priority needed at the requested period (0 none, 1 + priority)
/// bytes 5–6 shortest period accepted at the requested priority: sample time value, u16 (0 when none)
/// byte 7    bits 0–1 its unit; bits 2–3 violation kind (0 unknown, 1 board task, 2 bus message);
///           bits 4–5 the violated message's priority (0 unless a message); bit 6 set when a shortest period
///           is given; bit 7 reserved (0)
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct VerdictRequest {
    /// The topic the request was for.
    pub topic: Topic,
    /// The period requested.
    pub requested: SampleTime,
    /// The priority requested (the command's priority).
    pub priority: Priority,
    /// Refused or accepted with a warning.
    pub verdict: Verdict,
    /// The most urgent priority needed for the requested period to pass, `None` when no priority would do.
    pub priority_needed: Option<Priority>,
    /// The shortest period that would pass at the requested priority, `None` when none would.
    pub shortest_period: Option<SampleTime>,
    /// What kind of thing would miss its deadline.
    pub violation: ViolationKind,
    /// Whether the board searched for what would be accepted; when not (byte 7 bit 7 set), the priority needed
    /// and the shortest period are empty and say nothing.
    pub searched: bool,
    /// A one-shot (`once`) request, analysed as a sample every `requested` (in ms; byte 4 unit 3), not a publisher.
    pub one_shot: bool,
}

/// The second frame of an admission verdict (page 0x81): the bound that would break.
///
/// ```text
/// byte 1    the violated task's index, or the violated message's topic byte
/// bytes 2–4 its worst-case response time with the request, µs, u24 (saturated: 16.78 s or more, or unbounded)
/// bytes 5–7 its deadline, µs, u24 (saturated)
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct VerdictBound {
    /// Task index or topic byte (0 when the violation is unknown).
    pub violated: u8,
    /// Worst-case response time with the request in µs.
    pub wcrt_us: Count<24>,
    /// Deadline in µs.
    pub deadline_us: Count<24>,
}

/// One diagnostics frame, decoded: one page of a health sample, or one half of an admission verdict.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DiagnosticsPage {
    /// Page 0.
    Status {
        /// Seconds since the board started.
        uptime_s: u32,
        /// Why it last reset.
        reset_cause: ResetCause,
        /// Its state now.
        flags: StatusFlags,
        /// Sensor faults (failed reads, missing sensors) since boot.
        sensor_faults: Count<8>,
    },
    /// Page 1.
    Commands {
        /// Commands applied or handed to an actuator.
        accepted: Count<24>,
        /// Malformed commands rejected, every reason together.
        rejected: Count<24>,
        /// How many rejection reasons the board counts (its [`REJECT_REASONS`]).
        reasons: u8,
    },
    /// Page 2: three per-reason rejection counters.
    Rejections {
        /// The reason index (in [`DecodeError::KINDS`]) of the first counter.
        first: u8,
        /// The counters of reasons `first`, `first + 1`, `first + 2` (0 past the last reason).
        counts: [Count<16>; REJECTIONS_PER_SAMPLE],
    },
    /// Page 3.
    AdmissionAndReceive {
        /// Publish or re-prioritisation requests the admission check refused.
        refused: Count<16>,
        /// Requests carried out with a warning (policy accept-and-warn).
        warned: Count<16>,
        /// Received frames dropped (a lower bound: an overrun loses an unknown number of frames, counted as one).
        rx_dropped: Count<16>,
        /// Receive FIFO overruns.
        rx_overruns: Count<8>,
    },
    /// Page 4.
    Transmit {
        /// Frames the transmit queue dropped.
        tx_dropped: Count<24>,
        /// Queued samples displaced by newer samples of the same thing.
        tx_displaced: Count<16>,
        /// Times the CAN controller became error-passive.
        error_passive: Count<8>,
        /// Times it went bus-off.
        bus_off: Count<8>,
    },
    /// Page 5: deadline misses (releases skipped) per publisher level, urgent first.
    Deadlines {
        /// Indexed by `Priority as usize`.
        misses: [Count<14>; 4],
    },
    /// Page 0x80.
    VerdictRequest(VerdictRequest),
    /// Page 0x81.
    VerdictBound(VerdictBound),
}

/// Little-endian `u24` from three bytes.
const fn u24(b: [u8; 3]) -> u32 {
    u32::from_le_bytes([b[0], b[1], b[2], 0])
}

const fn u24_bytes(v: Count<24>) -> [u8; 3] {
    let [a, b, c, _] = v.get().to_le_bytes();
    [a, b, c]
}

const fn u16_bytes(v: Count<16>) -> [u8; 2] {
    // A Count<16> is at most u16::MAX, so the cast is exact.
    (v.get() as u16).to_le_bytes()
}

const fn u8_of(v: Count<8>) -> u8 {
    // A Count<8> is at most u8::MAX, so the cast is exact.
    v.get() as u8
}

fn c16(lo: u8, hi: u8) -> Count<16> {
    Count::saturating(u32::from(u16::from_le_bytes([lo, hi])))
}

impl DiagnosticsPage {
    /// The page byte (data\[0\]).
    pub const fn page(&self) -> u8 {
        self.byte_and_name().0
    }

    /// The page's name (`status`, `commands`, `rejections`, `admission-and-receive`, `transmit`, `deadlines`,
    /// `verdict`, `verdict-bound`).
    pub const fn name(&self) -> &'static str {
        self.byte_and_name().1
    }

    /// The page byte and the name of each page, in one table.
    const fn byte_and_name(&self) -> (u8, &'static str) {
        match self {
            DiagnosticsPage::Status { .. } => (0, "status"),
            DiagnosticsPage::Commands { .. } => (1, "commands"),
            DiagnosticsPage::Rejections { .. } => (2, "rejections"),
            DiagnosticsPage::AdmissionAndReceive { .. } => (3, "admission-and-receive"),
            DiagnosticsPage::Transmit { .. } => (4, "transmit"),
            DiagnosticsPage::Deadlines { .. } => (5, "deadlines"),
            DiagnosticsPage::VerdictRequest(_) => (VERDICT_PAGE, "verdict"),
            DiagnosticsPage::VerdictBound(_) => (VERDICT_BOUND_PAGE, "verdict-bound"),
        }
    }

    /// Checks the fields the decoder checks (only a verdict's sample times can be out of range).
    pub const fn validate(&self) -> Result<(), DecodeError> {
        match self {
            DiagnosticsPage::VerdictRequest(request) => {
                if let Err(e) = request.requested.validate() {
                    return Err(e);
                }
                match request.shortest_period {
                    Some(time) => time.validate(),
                    None => Ok(()),
                }
            }
            _ => Ok(()),
        }
    }

    /// The eight data bytes. Never fails; a verdict with a zero sample time gives bytes the decoder rejects.
    pub(crate) fn to_bytes(self) -> [u8; 8] {
        let page = self.page();
        match self {
            DiagnosticsPage::Status {
                uptime_s,
                reset_cause,
                flags,
                sensor_faults,
            } => {
                let [u0, u1, u2, u3] = uptime_s.to_le_bytes();
                [
                    page,
                    u0,
                    u1,
                    u2,
                    u3,
                    reset_cause.bits(),
                    flags.bits(),
                    u8_of(sensor_faults),
                ]
            }
            DiagnosticsPage::Commands {
                accepted,
                rejected,
                reasons,
            } => {
                let [a0, a1, a2] = u24_bytes(accepted);
                let [r0, r1, r2] = u24_bytes(rejected);
                [page, a0, a1, a2, r0, r1, r2, reasons]
            }
            DiagnosticsPage::Rejections { first, counts } => {
                let [a0, a1] = u16_bytes(counts[0]);
                let [b0, b1] = u16_bytes(counts[1]);
                let [c0, c1] = u16_bytes(counts[2]);
                [page, first, a0, a1, b0, b1, c0, c1]
            }
            DiagnosticsPage::AdmissionAndReceive {
                refused,
                warned,
                rx_dropped,
                rx_overruns,
            } => {
                let [r0, r1] = u16_bytes(refused);
                let [w0, w1] = u16_bytes(warned);
                let [d0, d1] = u16_bytes(rx_dropped);
                [page, r0, r1, w0, w1, d0, d1, u8_of(rx_overruns)]
            }
            DiagnosticsPage::Transmit {
                tx_dropped,
                tx_displaced,
                error_passive,
                bus_off,
            } => {
                let [d0, d1, d2] = u24_bytes(tx_dropped);
                let [p0, p1] = u16_bytes(tx_displaced);
                [
                    page,
                    d0,
                    d1,
                    d2,
                    p0,
                    p1,
                    u8_of(error_passive),
                    u8_of(bus_off),
                ]
            }
            DiagnosticsPage::Deadlines { misses } => {
                let mut packed: u64 = 0;
                let mut i = 0;
                while i < misses.len() {
                    packed |= u64::from(misses[i].get()) << (14 * i);
                    i += 1;
                }
                let [b0, b1, b2, b3, b4, b5, b6, _] = packed.to_le_bytes();
                [page, b0, b1, b2, b3, b4, b5, b6]
            }
            DiagnosticsPage::VerdictRequest(r) => {
                let [q0, q1] = r.requested.value.to_le_bytes();
                let needed = match r.priority_needed {
                    Some(p) => p as u8 + 1,
                    None => 0,
                };
                let unit = if r.one_shot {
                    ONE_SHOT_UNIT
                } else {
                    r.requested.unit as u8
                };
                let byte4 = unit
                    | ((r.priority as u8) << 2)
                    | (matches!(r.verdict, Verdict::AcceptedWithWarning) as u8) << 4
                    | (needed << 5);
                let (shortest, shortest_unit, has_shortest) = match r.shortest_period {
                    Some(time) => (time.value, time.unit as u8, 1u8),
                    None => (0, 0, 0),
                };
                let (kind, message_priority) = match r.violation {
                    ViolationKind::Unknown => (0u8, 0u8),
                    ViolationKind::Task => (1, 0),
                    ViolationKind::Message { priority } => (2, priority as u8),
                };
                let [s0, s1] = shortest.to_le_bytes();
                let byte7 = shortest_unit
                    | (kind << 2)
                    | (message_priority << 4)
                    | (has_shortest << 6)
                    | (u8::from(!r.searched) << 7);
                [page, r.topic.byte(), q0, q1, byte4, s0, s1, byte7]
            }
            DiagnosticsPage::VerdictBound(b) => {
                let [w0, w1, w2] = u24_bytes(b.wcrt_us);
                let [d0, d1, d2] = u24_bytes(b.deadline_us);
                [page, b.violated, w0, w1, w2, d0, d1, d2]
            }
        }
    }

    /// Decodes the eight data bytes of a frame on a diagnostics `topic`. Strict: every accepted frame re-encodes
    /// to the same bytes.
    pub(crate) fn from_bytes(topic: Topic, bytes: [u8; 8]) -> Result<DiagnosticsPage, DecodeError> {
        let [page, b1, b2, b3, b4, b5, b6, b7] = bytes;
        let reserved = |byte| DecodeError::ReservedBits { topic, byte };
        Ok(match page {
            0 => DiagnosticsPage::Status {
                uptime_s: u32::from_le_bytes([b1, b2, b3, b4]),
                reset_cause: ResetCause::from_bits(b5),
                flags: StatusFlags::from_bits(b6),
                sensor_faults: Count::saturating(u32::from(b7)),
            },
            1 => DiagnosticsPage::Commands {
                accepted: Count::saturating(u24([b1, b2, b3])),
                rejected: Count::saturating(u24([b4, b5, b6])),
                reasons: b7,
            },
            2 => DiagnosticsPage::Rejections {
                first: b1,
                counts: [c16(b2, b3), c16(b4, b5), c16(b6, b7)],
            },
            3 => DiagnosticsPage::AdmissionAndReceive {
                refused: c16(b1, b2),
                warned: c16(b3, b4),
                rx_dropped: c16(b5, b6),
                rx_overruns: Count::saturating(u32::from(b7)),
            },
            4 => DiagnosticsPage::Transmit {
                tx_dropped: Count::saturating(u24([b1, b2, b3])),
                tx_displaced: c16(b4, b5),
                error_passive: Count::saturating(u32::from(b6)),
                bus_off: Count::saturating(u32::from(b7)),
            },
            5 => {
                let packed = u64::from_le_bytes([b1, b2, b3, b4, b5, b6, b7, 0]);
                let miss = |i: u32| Count::saturating(((packed >> (14 * i)) & 0x3FFF) as u32);
                DiagnosticsPage::Deadlines {
                    misses: [miss(0), miss(1), miss(2), miss(3)],
                }
            }
            VERDICT_PAGE => {
                let requested_topic = Topic::try_from(b1)?;
                let one_shot = b4 & 0b11 == ONE_SHOT_UNIT;
                let unit = if one_shot {
                    TimeUnit::Millis
                } else {
                    TimeUnit::try_from(b4 & 0b11)?
                };
                let requested = SampleTime::new(u16::from_le_bytes([b2, b3]), unit)?;
                let priority = Priority::from_bits_truncate(b4 >> 2);
                let verdict = if b4 & (1 << 4) != 0 {
                    Verdict::AcceptedWithWarning
                } else {
                    Verdict::Refused
                };
                let priority_needed = match b4 >> 5 {
                    0 => None,
                    n @ 1..=4 => Some(Priority::from_bits_truncate(n - 1)),
                    _ => return Err(reserved(4)),
                };
                // Bit 7: the board did not search for what would be accepted; those fields are then empty.
                let searched = b7 & 0x80 == 0;
                if !searched && (priority_needed.is_some() || b7 & (1 << 6) != 0) {
                    return Err(reserved(7));
                }
                let shortest_period = if b7 & (1 << 6) != 0 {
                    Some(SampleTime::new(
                        u16::from_le_bytes([b5, b6]),
                        TimeUnit::try_from(b7 & 0b11)?,
                    )?)
                } else if b5 != 0 || b6 != 0 || b7 & 0b11 != 0 {
                    return Err(reserved(7));
                } else {
                    None
                };
                let message_priority = (b7 >> 4) & 0b11;
                let violation = match (b7 >> 2) & 0b11 {
                    0 if message_priority == 0 => ViolationKind::Unknown,
                    1 if message_priority == 0 => ViolationKind::Task,
                    2 => ViolationKind::Message {
                        priority: Priority::from_bits_truncate(message_priority),
                    },
                    _ => return Err(reserved(7)),
                };
                DiagnosticsPage::VerdictRequest(VerdictRequest {
                    topic: requested_topic,
                    requested,
                    priority,
                    verdict,
                    priority_needed,
                    shortest_period,
                    violation,
                    searched,
                    one_shot,
                })
            }
            VERDICT_BOUND_PAGE => DiagnosticsPage::VerdictBound(VerdictBound {
                violated: b1,
                wcrt_us: Count::saturating(u24([b2, b3, b4])),
                deadline_us: Count::saturating(u24([b5, b6, b7])),
            }),
            page => return Err(DecodeError::UnknownPage { topic, page }),
        })
    }
}

impl fmt::Display for DiagnosticsPage {
    /// `status: up 3600 s, last reset pin, flags watchdog, 0 sensor faults`, ...
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DiagnosticsPage::Status {
                uptime_s,
                reset_cause,
                flags,
                sensor_faults,
            } => write!(
                f,
                "status: up {uptime_s} s, last reset {reset_cause}, flags {flags}, {sensor_faults} sensor faults"
            ),
            DiagnosticsPage::Commands {
                accepted,
                rejected,
                reasons,
            } => write!(
                f,
                "commands: {accepted} accepted, {rejected} rejected ({reasons} reasons counted)"
            ),
            DiagnosticsPage::Rejections { first, counts } => {
                f.write_str("rejections:")?;
                for (i, count) in counts.iter().enumerate() {
                    let index = usize::from(*first) + i;
                    match DecodeError::KINDS.get(index) {
                        Some(name) => write!(f, " {name}={count}")?,
                        None => write!(f, " reason-{index}={count}")?,
                    }
                }
                Ok(())
            }
            DiagnosticsPage::AdmissionAndReceive {
                refused,
                warned,
                rx_dropped,
                rx_overruns,
            } => write!(
                f,
                "admission: {refused} refused, {warned} accepted with warning; receive: at least {rx_dropped} dropped, {rx_overruns} FIFO overruns"
            ),
            DiagnosticsPage::Transmit {
                tx_dropped,
                tx_displaced,
                error_passive,
                bus_off,
            } => write!(
                f,
                "transmit: {tx_dropped} dropped, {tx_displaced} displaced; bus: {error_passive} error-passive, {bus_off} bus-off"
            ),
            DiagnosticsPage::Deadlines { misses } => {
                f.write_str("deadline misses:")?;
                for (priority, count) in Priority::ALL.iter().zip(misses) {
                    write!(f, " {priority}={count}")?;
                }
                Ok(())
            }
            DiagnosticsPage::VerdictRequest(r) => {
                let verdict = r.verdict;
                if r.one_shot {
                    write!(
                        f,
                        "verdict: {verdict}: one-shot of {} at {} (analysed as every {})",
                        r.topic, r.priority, r.requested
                    )?;
                } else {
                    write!(
                        f,
                        "verdict: {verdict}: publish {} every {} at {}",
                        r.topic, r.requested, r.priority
                    )?;
                }
                if !r.searched {
                    return f.write_str("; what would pass not searched");
                }
                match r.shortest_period {
                    Some(time) => write!(f, "; shortest period at {}: {time}", r.priority)?,
                    None => write!(f, "; no period passes at {}", r.priority)?,
                }
                match r.priority_needed {
                    Some(p) => write!(f, "; priority needed at {}: {p}", r.requested),
                    None => write!(f, "; no priority passes at {}", r.requested),
                }
            }
            DiagnosticsPage::VerdictBound(b) => write!(
                f,
                "verdict bound: #{} responds in {} µs, deadline {} µs",
                b.violated, b.wcrt_us, b.deadline_us
            ),
        }
    }
}

/// What a request would break: a task of the board or a frame on the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Violation {
    /// Not named.
    Unknown,
    /// A task of the refusing board, by its index in the board's analysed task list (the order
    /// `cargo xtask analyze` reports).
    Task {
        /// The task index.
        index: u8,
    },
    /// A sensor-data frame on the bus (C/S = 1), by its identifier.
    Message {
        /// The identifier.
        id: CanId,
    },
}

/// An admission verdict, both frames together: a board refused a publish or re-prioritisation request (or
/// carried it out with a warning) because a task or a frame would miss its deadline.
///
/// A board builds one and sends [`AdmissionVerdict::frames`]; the operator pairs the two pages it hears on the
/// same identifier with [`AdmissionVerdict::from_pages`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct AdmissionVerdict {
    /// The board that decided (the owner of the diagnostics topic).
    pub board: Board,
    /// The topic the request was for.
    pub topic: Topic,
    /// The period requested.
    pub requested: SampleTime,
    /// The priority requested.
    pub priority: Priority,
    /// Refused or accepted with a warning.
    pub verdict: Verdict,
    /// What would miss its deadline.
    pub violation: Violation,
    /// Its worst-case response time with the request, µs (saturates at 16.78 s, also for "unbounded").
    pub wcrt_us: Count<24>,
    /// Its deadline, µs.
    pub deadline_us: Count<24>,
    /// The shortest period that would pass at the requested priority, `None` when none would.
    pub shortest_period: Option<SampleTime>,
    /// The most urgent priority needed for the requested period, `None` when no priority would do.
    pub priority_needed: Option<Priority>,
    /// Whether the board searched for what would be accepted (`shortest_period` and `priority_needed` are
    /// meaningful only then; the boards' on-chip check does not search).
    pub searched: bool,
    /// A one-shot (`once`) request, analysed as one sample every `requested` (the board's one-shot interval).
    pub one_shot: bool,
}

impl AdmissionVerdict {
    /// The two pages: [`VERDICT_PAGE`], then [`VERDICT_BOUND_PAGE`].
    pub fn pages(&self) -> [DiagnosticsPage; 2] {
        let (violation, violated) = match self.violation {
            Violation::Unknown => (ViolationKind::Unknown, 0),
            Violation::Task { index } => (ViolationKind::Task, index),
            Violation::Message { id } => (
                ViolationKind::Message {
                    priority: id.priority(),
                },
                id.topic_byte(),
            ),
        };
        [
            DiagnosticsPage::VerdictRequest(VerdictRequest {
                topic: self.topic,
                requested: self.requested,
                priority: self.priority,
                verdict: self.verdict,
                priority_needed: self.priority_needed,
                shortest_period: self.shortest_period,
                violation,
                searched: self.searched,
                one_shot: self.one_shot,
            }),
            DiagnosticsPage::VerdictBound(VerdictBound {
                violated,
                wcrt_us: self.wcrt_us,
                deadline_us: self.deadline_us,
            }),
        ]
    }

    /// The two frames to send, in order, on the board's diagnostics topic at `priority` (the priority of the
    /// request they answer).
    pub fn frames(&self, priority: Priority) -> [Frame; 2] {
        self.pages().map(|page| {
            SensorData::Diagnostics {
                board: self.board,
                page,
            }
            .encode(priority)
        })
    }

    /// The verdict from its two pages, heard from `board`.
    pub fn from_pages(board: Board, request: &VerdictRequest, bound: &VerdictBound) -> Self {
        let violation = match request.violation {
            ViolationKind::Unknown => Violation::Unknown,
            ViolationKind::Task => Violation::Task {
                index: bound.violated,
            },
            ViolationKind::Message { priority } => Violation::Message {
                id: CanId::new(Kind::Sensor, priority, bound.violated),
            },
        };
        AdmissionVerdict {
            board,
            topic: request.topic,
            requested: request.requested,
            priority: request.priority,
            verdict: request.verdict,
            violation,
            wcrt_us: bound.wcrt_us,
            deadline_us: bound.deadline_us,
            shortest_period: request.shortest_period,
            priority_needed: request.priority_needed,
            searched: request.searched,
            one_shot: request.one_shot,
        }
    }
}

impl fmt::Display for AdmissionVerdict {
    /// Plain English, e.g. `DiWheelDrive refused "publish accelerometer every 1 µs at urgent": its task #4 would
    /// respond in 16777215+ µs but must within 1 µs. At urgent it accepts every 2 ms or slower; no priority makes
    /// 1 µs pass.`
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let decided = self.verdict;
        if self.one_shot {
            write!(
                f,
                "{} {decided} \"once {} at {}\" (a sample every {}): ",
                self.board, self.topic, self.priority, self.requested
            )?;
        } else {
            write!(
                f,
                "{} {decided} \"publish {} every {} at {}\": ",
                self.board, self.topic, self.requested, self.priority
            )?;
        }
        match self.violation {
            // No deadline named and no bound: the board's check decided without a verdict on any deadline (its
            // working arrays too small for the set, its fixed-point iteration budget spent, or a zero period;
            // the board's diagnostics count which). Refusing never breaks a deadline.
            Violation::Unknown if self.deadline_us.get() == 0 && self.wcrt_us.get() == 0 => {
                f.write_str(
                    "its check reached no verdict on a deadline (the set is beyond its capacity or its iteration \
                     budget, or the period is zero; the diagnostics' admission reasons say which), so it refuses.",
                )?;
                if !self.searched {
                    return f.write_str(" The board did not search for what it would accept.");
                }
                return Ok(());
            }
            Violation::Unknown => f.write_str("a deadline would be missed")?,
            Violation::Task { index } => write!(f, "its task #{index} would miss its deadline")?,
            Violation::Message { id } => match Topic::from_byte(id.topic_byte()) {
                Some(topic) => write!(
                    f,
                    "{} {topic} frames (0x{:03X}) would miss their deadline",
                    id.priority(),
                    id.raw()
                )?,
                None => write!(f, "frames 0x{:03X} would miss their deadline", id.raw())?,
            },
        }
        write!(
            f,
            " (worst-case response {} µs, deadline {} µs).",
            self.wcrt_us, self.deadline_us
        )?;
        if !self.searched {
            return f.write_str(" The board did not search for what it would accept.");
        }
        match self.shortest_period {
            Some(time) => write!(
                f,
                " At {} it accepts every {time} or slower;",
                self.priority
            )?,
            None => write!(f, " No period passes at {};", self.priority)?,
        }
        match self.priority_needed {
            Some(p) => write!(
                f,
                " every {} needs priority {p} or more urgent.",
                self.requested
            ),
            None => write!(f, " no priority makes every {} pass.", self.requested),
        }
    }
}

/// A board's health counters, as the board keeps them (`u32`, saturating) — the source of one diagnostics
/// sample ([`Diagnostics::frames`]), and on the host the sum of the pages heard ([`Diagnostics::absorb`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Diagnostics {
    /// Seconds since the board started.
    pub uptime_s: u32,
    /// Why it last reset.
    pub reset_cause: ResetCause,
    /// Its state now.
    pub flags: StatusFlags,
    /// Sensor faults since boot.
    pub sensor_faults: u32,
    /// Commands applied or handed to an actuator.
    pub accepted: u32,
    /// Malformed commands, one counter per [`DecodeError::kind_index`].
    pub rejected: [u32; REJECT_REASONS],
    /// Requests the admission check refused.
    pub admission_refused: u32,
    /// Requests carried out with a warning.
    pub admission_warned: u32,
    /// Admission verdicts (refused or carried out with a warning), one counter per [`RefusalReason`].
    pub refusals: [u32; REFUSAL_REASONS],
    /// Received frames dropped (a lower bound).
    pub rx_dropped: u32,
    /// Receive FIFO overruns.
    pub rx_overruns: u32,
    /// Frames the transmit queue dropped.
    pub tx_dropped: u32,
    /// Queued samples displaced by newer ones.
    pub tx_displaced: u32,
    /// Error-passive episodes of the CAN controller.
    pub error_passive: u32,
    /// Bus-off episodes.
    pub bus_off: u32,
    /// Deadline misses per publisher level, indexed by `Priority as usize`.
    pub deadline_misses: [u32; 4],
}

impl Diagnostics {
    /// Everything zero.
    pub const ZERO: Diagnostics = Diagnostics {
        uptime_s: 0,
        reset_cause: ResetCause::NONE,
        flags: StatusFlags::NONE,
        sensor_faults: 0,
        accepted: 0,
        rejected: [0; REJECT_REASONS],
        admission_refused: 0,
        admission_warned: 0,
        refusals: [0; REFUSAL_REASONS],
        rx_dropped: 0,
        rx_overruns: 0,
        tx_dropped: 0,
        tx_displaced: 0,
        error_passive: 0,
        bus_off: 0,
        deadline_misses: [0; 4],
    };

    /// Rejected commands, every reason together (saturating).
    pub fn rejected_total(&self) -> u32 {
        self.rejected
            .iter()
            .fold(0u32, |sum, count| sum.saturating_add(*count))
    }

    /// The rejection window of the sample after one with `window`: three reasons on, back to 0 after the last.
    pub const fn next_window(window: u8) -> u8 {
        let next = window as usize + REJECTIONS_PER_SAMPLE;
        if next >= COUNTED_REASONS {
            0
        } else {
            // Below COUNTED_REASONS, which fits a u8 (checked above).
            next as u8
        }
    }

    /// The counter of page 2's reason `index` ([`reason_name`]), `None` past [`COUNTED_REASONS`].
    pub fn reason_count(&self, index: usize) -> Option<u32> {
        match index.checked_sub(REJECT_REASONS) {
            None => self.rejected.get(index).copied(),
            Some(i) => self.refusals.get(i).copied(),
        }
    }

    /// The counter of page 2's reason `index`, to be set (`None` past [`COUNTED_REASONS`]).
    fn reason_slot(&mut self, index: usize) -> Option<&mut u32> {
        match index.checked_sub(REJECT_REASONS) {
            None => self.rejected.get_mut(index),
            Some(i) => self.refusals.get_mut(i),
        }
    }

    /// The six pages of one sample; page 2 carries the counters of reasons `window..window + 3`.
    pub fn pages(&self, window: u8) -> [DiagnosticsPage; PAGES_PER_SAMPLE as usize] {
        let reason = |i: usize| {
            let count = self.reason_count(usize::from(window) + i);
            Count::saturating(count.unwrap_or(0))
        };
        [
            DiagnosticsPage::Status {
                uptime_s: self.uptime_s,
                reset_cause: self.reset_cause,
                flags: self.flags,
                sensor_faults: Count::saturating(self.sensor_faults),
            },
            DiagnosticsPage::Commands {
                accepted: Count::saturating(self.accepted),
                rejected: Count::saturating(self.rejected_total()),
                // Fits: checked above.
                reasons: COUNTED_REASONS as u8,
            },
            DiagnosticsPage::Rejections {
                first: window,
                counts: [reason(0), reason(1), reason(2)],
            },
            DiagnosticsPage::AdmissionAndReceive {
                refused: Count::saturating(self.admission_refused),
                warned: Count::saturating(self.admission_warned),
                rx_dropped: Count::saturating(self.rx_dropped),
                rx_overruns: Count::saturating(self.rx_overruns),
            },
            DiagnosticsPage::Transmit {
                tx_dropped: Count::saturating(self.tx_dropped),
                tx_displaced: Count::saturating(self.tx_displaced),
                error_passive: Count::saturating(self.error_passive),
                bus_off: Count::saturating(self.bus_off),
            },
            DiagnosticsPage::Deadlines {
                misses: self.deadline_misses.map(Count::saturating),
            },
        ]
    }

    /// The frames of one sample of `board`'s diagnostics topic at `priority`, pages 0 to 5 in order.
    pub fn frames(
        &self,
        board: Board,
        priority: Priority,
        window: u8,
    ) -> [Frame; PAGES_PER_SAMPLE as usize] {
        self.pages(window)
            .map(|page| SensorData::Diagnostics { board, page }.encode(priority))
    }

    /// Folds one decoded page into these counters (host side: build the board's picture from what is heard).
    /// Saturated values stay saturated; page 1's rejected total is not stored (it is the sum of the reasons);
    /// verdict pages change nothing.
    pub fn absorb(&mut self, page: &DiagnosticsPage) {
        match *page {
            DiagnosticsPage::Status {
                uptime_s,
                reset_cause,
                flags,
                sensor_faults,
            } => {
                self.uptime_s = uptime_s;
                self.reset_cause = reset_cause;
                self.flags = flags;
                self.sensor_faults = sensor_faults.get();
            }
            DiagnosticsPage::Commands { accepted, .. } => self.accepted = accepted.get(),
            DiagnosticsPage::Rejections { first, counts } => {
                for (i, count) in counts.iter().enumerate() {
                    if let Some(slot) = self.reason_slot(usize::from(first) + i) {
                        *slot = count.get();
                    }
                }
            }
            DiagnosticsPage::AdmissionAndReceive {
                refused,
                warned,
                rx_dropped,
                rx_overruns,
            } => {
                self.admission_refused = refused.get();
                self.admission_warned = warned.get();
                self.rx_dropped = rx_dropped.get();
                self.rx_overruns = rx_overruns.get();
            }
            DiagnosticsPage::Transmit {
                tx_dropped,
                tx_displaced,
                error_passive,
                bus_off,
            } => {
                self.tx_dropped = tx_dropped.get();
                self.tx_displaced = tx_displaced.get();
                self.error_passive = error_passive.get();
                self.bus_off = bus_off.get();
            }
            DiagnosticsPage::Deadlines { misses } => {
                self.deadline_misses = misses.map(Count::get);
            }
            DiagnosticsPage::VerdictRequest(_) | DiagnosticsPage::VerdictBound(_) => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_saturate() {
        assert_eq!(Count::<24>::MAX, 0xFF_FFFF);
        assert_eq!(Count::<14>::saturating(20_000).get(), 16_383);
        assert!(Count::<8>::saturating(256).is_saturated());
        assert_eq!(std::format!("{}", Count::<8>::saturating(300)), "255+");
        assert_eq!(std::format!("{}", Count::<8>::saturating(3)), "3");
    }

    /// A diagnostics frame's first byte is one of eight pages: a sample's 0–5 and a verdict's two.
    /// DiWheelDrive's bounds file states the transmit queue's walk over the queued frames of one
    /// diagnostics identifier at these eight (a newer frame of a page replaces the queued one) and
    /// the one that ends the walk; every page the encoder writes decodes (strict round trip), so
    /// the decoder's pages bound the encoder's.
    #[test]
    fn a_diagnostics_frame_carries_one_of_eight_page_bytes() {
        let pages: std::vec::Vec<u8> = (0..=u8::MAX)
            .filter(|&page| {
                !matches!(
                    DiagnosticsPage::from_bytes(
                        Topic::DiWheelDriveDiagnostics,
                        [page, 0, 0, 0, 0, 0, 0, 0]
                    ),
                    Err(DecodeError::UnknownPage { .. })
                )
            })
            .collect();
        assert_eq!(pages, [0, 1, 2, 3, 4, 5, VERDICT_PAGE, VERDICT_BOUND_PAGE]);
        assert_eq!(PAGES_PER_SAMPLE, 6);
        for page in Diagnostics::ZERO.pages(0) {
            assert!(pages.contains(&page.page()), "sample page {}", page.page());
        }
    }

    #[test]
    fn windows_cycle_through_every_reason() {
        let mut window = 0u8;
        let mut seen = [false; COUNTED_REASONS];
        for _ in 0..COUNTED_REASONS.div_ceil(REJECTIONS_PER_SAMPLE) {
            for i in 0..REJECTIONS_PER_SAMPLE {
                if let Some(s) = seen.get_mut(usize::from(window) + i) {
                    *s = true;
                }
            }
            window = Diagnostics::next_window(window);
        }
        assert!(seen.iter().all(|s| *s));
        assert_eq!(window, 0, "the window returns to 0 after one cycle");
    }

    #[test]
    fn refusal_reasons_follow_the_rejection_reasons_on_page_2() {
        let mut board = Diagnostics::ZERO;
        board.rejected[DecodeError::KINDS.len() - 1] = 7;
        board.refusals[RefusalReason::MessageDeadline as usize] = 3;
        board.refusals[RefusalReason::ZeroPeriod as usize] = 1;
        let mut heard = Diagnostics::ZERO;
        let mut window = 0u8;
        loop {
            for page in board.pages(window) {
                heard.absorb(&page);
            }
            window = Diagnostics::next_window(window);
            if window == 0 {
                break;
            }
        }
        assert_eq!(heard.rejected, board.rejected);
        assert_eq!(heard.refusals, board.refusals);
        let index = RefusalReason::MessageDeadline.counted_index();
        assert_eq!(reason_name(index), Some("admission-message-deadline"));
        assert_eq!(reason_name(0), Some(DecodeError::KINDS[0]));
        assert_eq!(reason_name(COUNTED_REASONS), None);
        assert_eq!(heard.reason_count(index), Some(3));
        // Page 1 counts the malformed commands only, and says how many reasons page 2 cycles through.
        let DiagnosticsPage::Commands {
            rejected, reasons, ..
        } = board.pages(0)[1]
        else {
            panic!("page 1")
        };
        assert_eq!((rejected.get(), usize::from(reasons)), (7, COUNTED_REASONS));
    }

    #[test]
    fn flags_display() {
        let cause = ResetCause::PIN.with(ResetCause::INDEPENDENT_WATCHDOG);
        assert_eq!(std::format!("{cause}"), "pin+independent-watchdog");
        assert!(cause.contains(ResetCause::PIN));
        assert!(!cause.contains(ResetCause::FAULT));
        assert_eq!(std::format!("{}", StatusFlags::NONE), "none");
    }
}
