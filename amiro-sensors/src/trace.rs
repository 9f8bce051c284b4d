//! Trace events of the sensor-data handler: what happened when, in a small `Copy` type that a
//! firmware sends over RTT in a fixed-size binary record or prints as one text line in QEMU.
//!
//! Binary record ([`TraceEvent::encode`], [`ENCODED_LEN`] bytes, little-endian):
//!
//! ```text
//! byte 0      kind tag (see TraceKind::tag)
//! bytes 1..9  at_us, u64
//! bytes 9..18 payload, zero-padded; its layout depends on the tag
//! ```
//!
//! Text line ([`core::fmt::Display`]): `(0.001800) trace sample-taken magnetometer-x release=0.001800`
//! — seconds with microsecond digits, the word `trace`, the kind's name, its fields.

use core::fmt;

use amiro_can::{DecodeError, Topic};

use crate::handler::{Outcome, Rejection};
use crate::tx_queue::PushOutcome;

/// The kinds whose one field is a frame identifier, the identifier bound to `$id`: one list for the
/// binary record and the text line, which treat them alike.
macro_rules! frame_id_kinds {
    ($id:ident) => {
        TraceKind::CommandAccepted { id: $id }
            | TraceKind::CommandIgnored { id: $id }
            | TraceKind::FrameQueued { id: $id }
            | TraceKind::FrameReplaced { id: $id }
            | TraceKind::FrameSent { id: $id }
            | TraceKind::QueueOverflow { id: $id }
    };
}

/// Size of one encoded trace record.
pub const ENCODED_LEN: usize = 18;

const PAYLOAD_AT: usize = 9;

// The largest payloads, topic + u64 (sample-taken) and topic + two u32 (deadline-missed), must fit.
const _: () = assert!(PAYLOAD_AT + 1 + 8 <= ENCODED_LEN && PAYLOAD_AT + 1 + 4 + 4 <= ENCODED_LEN);

/// Why the motors were stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum StopReason {
    /// No motor command arrived within the dead-man time.
    DeadMan,
    /// Another module requested shutdown (SYS_PD_N fell).
    Shutdown,
    /// A panic or a HardFault.
    Fault,
}

impl StopReason {
    const ALL: [StopReason; 3] = [StopReason::DeadMan, StopReason::Shutdown, StopReason::Fault];

    /// The name used in text traces (`dead-man`, `shutdown`, `fault`).
    pub const fn name(self) -> &'static str {
        match self {
            StopReason::DeadMan => "dead-man",
            StopReason::Shutdown => "shutdown",
            StopReason::Fault => "fault",
        }
    }

    const fn code(self) -> u8 {
        match self {
            StopReason::DeadMan => 0,
            StopReason::Shutdown => 1,
            StopReason::Fault => 2,
        }
    }
}

/// Why a command was rejected, as far as a trace keeps it: the kind of [`DecodeError`] (its
/// index in [`DecodeError::KINDS`]), without the variant's details.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct RejectReason(u8);

impl RejectReason {
    /// The reason with this index in [`DecodeError::KINDS`], if there is one.
    pub fn from_index(index: usize) -> Option<RejectReason> {
        if index < DecodeError::KINDS.len() {
            u8::try_from(index).ok().map(RejectReason)
        } else {
            None
        }
    }

    /// The index in [`DecodeError::KINDS`] (the handler's counter index).
    pub fn index(self) -> usize {
        usize::from(self.0)
    }

    /// The stable short name (`bad-unit`, `dlc-too-short`, ...).
    pub fn name(self) -> &'static str {
        DecodeError::KINDS
            .get(self.index())
            .copied()
            .unwrap_or("unknown")
    }
}

impl From<DecodeError> for RejectReason {
    fn from(error: DecodeError) -> Self {
        // kind_index() is below KINDS.len(), which is far below 256.
        RejectReason(u8::try_from(error.kind_index()).unwrap_or(u8::MAX))
    }
}

/// What happened.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TraceKind {
    /// A command was applied or handed to an actuator.
    CommandAccepted {
        /// Raw identifier of the command frame.
        id: u16,
    },
    /// A malformed command was refused; nothing changed.
    CommandRejected {
        /// Raw identifier of the frame (may be out of the 11-bit range: that is one reason).
        id: u16,
        /// Why.
        reason: RejectReason,
    },
    /// A frame for another board, or a sensor-data frame.
    CommandIgnored {
        /// Raw identifier of the frame.
        id: u16,
    },
    /// A publisher task took a sample.
    SampleTaken {
        /// The topic sampled.
        topic: Topic,
        /// The release the sample serves; `at_us - release_us` is the release jitter.
        release_us: u64,
    },
    /// A frame entered the transmit queue.
    FrameQueued {
        /// Its identifier.
        id: u16,
    },
    /// An older sample still waiting in the transmit queue was replaced by a newer one.
    FrameReplaced {
        /// Their identifier.
        id: u16,
    },
    /// A frame went to a CAN mailbox.
    FrameSent {
        /// Its identifier.
        id: u16,
    },
    /// A publisher fell a full period or more behind; the skipped releases are lost.
    DeadlineMissed {
        /// The topic.
        topic: Topic,
        /// Releases skipped.
        missed: u32,
        /// How far past its deadline the oldest skipped release was, saturated at `u32::MAX` µs.
        late_us: u32,
    },
    /// The transmit queue was full and dropped a frame.
    QueueOverflow {
        /// The identifier of the dropped frame.
        id: u16,
    },
    /// The motors were stopped.
    MotorsStopped {
        /// Why.
        reason: StopReason,
    },
    /// Trace events lost because the trace buffer was full (emitted when it drains).
    EventsLost {
        /// How many.
        count: u32,
    },
    /// An LED command set an LED's colour in the board's LED state (LightRing).
    LedSet {
        /// Protocol LED number, 1..=8.
        led: u8,
        /// Red, green, blue as commanded.
        rgb: [u8; 3],
    },
    /// The LED state was shifted into the LED driver and latched: every LED now shows its colour
    /// (LightRing). `changed` has bit n−1 set for each LED n whose colour changed with this latch.
    LedsLatched {
        /// LEDs whose colour changed.
        changed: u8,
    },
    /// The CAN controller's error state changed (error-active 0, warning 1, passive 2, bus-off 3).
    CanBusState {
        /// The state now.
        state: u8,
        /// Transmit error counter.
        tec: u8,
        /// Receive error counter.
        rec: u8,
    },
}

impl TraceKind {
    /// The kind for what [`SensorDataHandler::on_frame`](crate::handler::SensorDataHandler::on_frame)
    /// returned for the frame with identifier `id`.
    pub fn for_command(id: u16, result: &Result<Outcome, Rejection>) -> TraceKind {
        match result {
            Ok(Outcome::Ignored(_)) => TraceKind::CommandIgnored { id },
            Ok(_) => TraceKind::CommandAccepted { id },
            Err(rejection) => TraceKind::CommandRejected {
                id,
                reason: rejection.reason.into(),
            },
        }
    }

    /// The kinds for what [`TxQueue::push`](crate::tx_queue::TxQueue::push) did with a frame
    /// with identifier `id`: one or two (queued, and another frame dropped to make room).
    pub fn for_push(id: u16, outcome: &PushOutcome) -> impl Iterator<Item = TraceKind> {
        let (first, second) = Self::push_kinds(id, outcome);
        core::iter::once(first).chain(second)
    }

    /// [`for_push`](Self::for_push)'s kinds as a pair: the first, and the second where there is
    /// one (for a writer that stores them without an iterator's state).
    #[inline]
    pub fn push_kinds(id: u16, outcome: &PushOutcome) -> (TraceKind, Option<TraceKind>) {
        match outcome {
            PushOutcome::Queued => (TraceKind::FrameQueued { id }, None),
            PushOutcome::Replaced { .. } => (TraceKind::FrameReplaced { id }, None),
            PushOutcome::DroppedOther { dropped } => (
                TraceKind::FrameQueued { id },
                Some(TraceKind::QueueOverflow {
                    id: dropped.id().raw(),
                }),
            ),
            PushOutcome::DroppedNew { .. } => (TraceKind::QueueOverflow { id }, None),
        }
    }

    /// The kind for a release that skipped earlier ones, if it did.
    pub fn for_release(release: &crate::handler::Release) -> Option<TraceKind> {
        (release.missed > 0).then(|| TraceKind::DeadlineMissed {
            topic: release.topic,
            missed: release.missed,
            late_us: u32::try_from(release.late_us).unwrap_or(u32::MAX),
        })
    }

    /// The kind's name in text traces.
    pub const fn name(&self) -> &'static str {
        match self {
            TraceKind::CommandAccepted { .. } => "command-accepted",
            TraceKind::CommandRejected { .. } => "command-rejected",
            TraceKind::CommandIgnored { .. } => "command-ignored",
            TraceKind::SampleTaken { .. } => "sample-taken",
            TraceKind::FrameQueued { .. } => "frame-queued",
            TraceKind::FrameReplaced { .. } => "frame-replaced",
            TraceKind::FrameSent { .. } => "frame-sent",
            TraceKind::DeadlineMissed { .. } => "deadline-missed",
            TraceKind::QueueOverflow { .. } => "queue-overflow",
            TraceKind::MotorsStopped { .. } => "motors-stopped",
            TraceKind::EventsLost { .. } => "events-lost",
            TraceKind::LedSet { .. } => "led-set",
            TraceKind::LedsLatched { .. } => "leds-latched",
            TraceKind::CanBusState { .. } => "can-bus-state",
        }
    }

    /// The tag byte of the binary record. Stable: new kinds get new numbers.
    pub const fn tag(&self) -> u8 {
        match self {
            TraceKind::CommandAccepted { .. } => 1,
            TraceKind::CommandRejected { .. } => 2,
            TraceKind::CommandIgnored { .. } => 3,
            TraceKind::SampleTaken { .. } => 4,
            TraceKind::FrameQueued { .. } => 5,
            TraceKind::FrameReplaced { .. } => 6,
            TraceKind::FrameSent { .. } => 7,
            TraceKind::DeadlineMissed { .. } => 8,
            TraceKind::QueueOverflow { .. } => 9,
            TraceKind::MotorsStopped { .. } => 10,
            TraceKind::EventsLost { .. } => 11,
            TraceKind::LedSet { .. } => 12,
            TraceKind::LedsLatched { .. } => 13,
            TraceKind::CanBusState { .. } => 14,
        }
    }
}

/// Why a binary trace record could not be decoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TraceDecodeError {
    /// The record is not [`ENCODED_LEN`] bytes.
    WrongLength {
        /// The length given.
        len: usize,
    },
    /// The tag byte names no kind.
    UnknownTag {
        /// The tag.
        tag: u8,
    },
    /// A topic byte names no topic.
    UnknownTopic {
        /// The byte.
        byte: u8,
    },
    /// A reject-reason index beyond [`DecodeError::KINDS`].
    UnknownRejectReason {
        /// The index.
        index: u8,
    },
    /// A stop-reason code that names no reason.
    UnknownStopReason {
        /// The code.
        code: u8,
    },
    /// Payload bytes past the kind's fields are not zero (a corrupt or misaligned record).
    TrailingBytes,
}

impl fmt::Display for TraceDecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            TraceDecodeError::WrongLength { len } => {
                write!(f, "trace record of {len} bytes, expected {ENCODED_LEN}")
            }
            TraceDecodeError::UnknownTag { tag } => write!(f, "unknown trace tag {tag}"),
            TraceDecodeError::UnknownTopic { byte } => write!(f, "unknown topic 0x{byte:02X}"),
            TraceDecodeError::UnknownRejectReason { index } => {
                write!(f, "unknown reject reason {index}")
            }
            TraceDecodeError::UnknownStopReason { code } => write!(f, "unknown stop reason {code}"),
            TraceDecodeError::TrailingBytes => f.write_str("non-zero padding in trace record"),
        }
    }
}

/// One trace event: when (µs of the firmware's monotonic clock) and what.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct TraceEvent {
    /// When it happened, µs since boot.
    pub at_us: u64,
    /// What happened.
    pub kind: TraceKind,
}

impl TraceEvent {
    /// An event at `at_us`.
    pub const fn new(at_us: u64, kind: TraceKind) -> Self {
        Self { at_us, kind }
    }

    /// The fixed-size binary record (layout in the module documentation).
    pub fn encode(&self) -> [u8; ENCODED_LEN] {
        let mut record = [0u8; ENCODED_LEN];
        let mut writer = Writer {
            record: &mut record,
            at: 0,
        };
        writer.put(&[self.kind.tag()]);
        writer.put(&self.at_us.to_le_bytes());
        match self.kind {
            frame_id_kinds!(id) => writer.put(&id.to_le_bytes()),
            TraceKind::CommandRejected { id, reason } => {
                writer.put(&id.to_le_bytes());
                writer.put(&[reason.0]);
            }
            TraceKind::SampleTaken { topic, release_us } => {
                writer.put(&[topic.byte()]);
                writer.put(&release_us.to_le_bytes());
            }
            TraceKind::DeadlineMissed {
                topic,
                missed,
                late_us,
            } => {
                writer.put(&[topic.byte()]);
                writer.put(&missed.to_le_bytes());
                writer.put(&late_us.to_le_bytes());
            }
            TraceKind::MotorsStopped { reason } => writer.put(&[reason.code()]),
            TraceKind::EventsLost { count } => writer.put(&count.to_le_bytes()),
            TraceKind::LedSet { led, rgb } => {
                writer.put(&[led]);
                writer.put(&rgb);
            }
            TraceKind::LedsLatched { changed } => writer.put(&[changed]),
            TraceKind::CanBusState { state, tec, rec } => writer.put(&[state, tec, rec]),
        }
        record
    }

    /// Reads a record written by [`encode`](Self::encode).
    pub fn decode(record: &[u8]) -> Result<TraceEvent, TraceDecodeError> {
        let record: &[u8; ENCODED_LEN] = record
            .try_into()
            .map_err(|_| TraceDecodeError::WrongLength { len: record.len() })?;
        let mut reader = Reader { record, at: 0 };
        let tag = reader.u8();
        let at_us = reader.u64();
        let topic =
            |byte: u8| Topic::from_byte(byte).ok_or(TraceDecodeError::UnknownTopic { byte });
        let kind = match tag {
            1 => TraceKind::CommandAccepted { id: reader.u16() },
            2 => {
                let id = reader.u16();
                let index = reader.u8();
                let reason = RejectReason::from_index(usize::from(index))
                    .ok_or(TraceDecodeError::UnknownRejectReason { index })?;
                TraceKind::CommandRejected { id, reason }
            }
            3 => TraceKind::CommandIgnored { id: reader.u16() },
            4 => TraceKind::SampleTaken {
                topic: topic(reader.u8())?,
                release_us: reader.u64(),
            },
            5 => TraceKind::FrameQueued { id: reader.u16() },
            6 => TraceKind::FrameReplaced { id: reader.u16() },
            7 => TraceKind::FrameSent { id: reader.u16() },
            8 => TraceKind::DeadlineMissed {
                topic: topic(reader.u8())?,
                missed: reader.u32(),
                late_us: reader.u32(),
            },
            9 => TraceKind::QueueOverflow { id: reader.u16() },
            10 => {
                let code = reader.u8();
                let reason = StopReason::ALL
                    .into_iter()
                    .find(|reason| reason.code() == code)
                    .ok_or(TraceDecodeError::UnknownStopReason { code })?;
                TraceKind::MotorsStopped { reason }
            }
            11 => TraceKind::EventsLost {
                count: reader.u32(),
            },
            12 => TraceKind::LedSet {
                led: reader.u8(),
                rgb: [reader.u8(), reader.u8(), reader.u8()],
            },
            13 => TraceKind::LedsLatched {
                changed: reader.u8(),
            },
            14 => TraceKind::CanBusState {
                state: reader.u8(),
                tec: reader.u8(),
                rec: reader.u8(),
            },
            tag => return Err(TraceDecodeError::UnknownTag { tag }),
        };
        if reader.rest().iter().any(|byte| *byte != 0) {
            return Err(TraceDecodeError::TrailingBytes);
        }
        Ok(TraceEvent { at_us, kind })
    }
}

/// Writes fields one after another into a record; every kind's fields fit (checked by a test),
/// and a field that did not would be cut short rather than panic.
struct Writer<'a> {
    record: &'a mut [u8; ENCODED_LEN],
    at: usize,
}

impl Writer<'_> {
    // A field of a fixed size: each call copies its K bytes without a length to look up (no
    // `memcpy` of a length the machine code does not fix: docs/analysis.md).
    fn put<const K: usize>(&mut self, bytes: &[u8; K]) {
        for (k, &byte) in bytes.iter().enumerate() {
            if let Some(slot) = self.record.get_mut(self.at + k) {
                *slot = byte;
            }
        }
        self.at = self.at.saturating_add(K).min(ENCODED_LEN);
    }
}

/// Reads fields one after another; past the end it reads zeros (cannot happen for a full record).
struct Reader<'a> {
    record: &'a [u8; ENCODED_LEN],
    at: usize,
}

impl Reader<'_> {
    fn take<const K: usize>(&mut self) -> [u8; K] {
        let mut out = [0u8; K];
        let end = self.at.saturating_add(K).min(ENCODED_LEN);
        if let Some(src) = self.record.get(self.at..end) {
            for (dst, byte) in out.iter_mut().zip(src) {
                *dst = *byte;
            }
        }
        self.at = end;
        out
    }

    fn u8(&mut self) -> u8 {
        let [byte] = self.take::<1>();
        byte
    }

    fn u16(&mut self) -> u16 {
        u16::from_le_bytes(self.take())
    }

    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take())
    }

    fn u64(&mut self) -> u64 {
        u64::from_le_bytes(self.take())
    }

    fn rest(&self) -> &[u8] {
        self.record.get(self.at.max(PAYLOAD_AT)..).unwrap_or(&[])
    }
}

/// Seconds with six decimals, as candump logs print time: `0.001800`.
struct Seconds(u64);

impl fmt::Display for Seconds {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // The timestamp's text is `amiro_can::candump`'s, which the log readers parse.
        fmt::Display::fmt(&amiro_can::candump::Timestamp::from_micros(self.0), f)
    }
}

impl fmt::Display for TraceEvent {
    /// One line: `(0.001800) trace sample-taken magnetometer-x release=0.001800`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "({}) trace {}", Seconds(self.at_us), self.kind.name())?;
        match self.kind {
            // Identifiers as can-utils print them (three hex digits).
            frame_id_kinds!(id) => write!(f, " {id:03X}"),
            TraceKind::CommandRejected { id, reason } => write!(f, " {id:03X} {}", reason.name()),
            TraceKind::SampleTaken { topic, release_us } => {
                write!(f, " {topic} release={}", Seconds(release_us))
            }
            TraceKind::DeadlineMissed {
                topic,
                missed,
                late_us,
            } => write!(f, " {topic} missed={missed} late={late_us}us"),
            TraceKind::MotorsStopped { reason } => write!(f, " {}", reason.name()),
            TraceKind::EventsLost { count } => write!(f, " count={count}"),
            TraceKind::LedSet {
                led,
                rgb: [r, g, b],
            } => {
                write!(f, " led={led} rgb={r:02X}{g:02X}{b:02X}")
            }
            TraceKind::LedsLatched { changed } => write!(f, " changed={changed:08b}"),
            TraceKind::CanBusState { state, tec, rec } => {
                write!(f, " state={state} tec={tec} rec={rec}")
            }
        }
    }
}

/// A bounded buffer of trace events between the tasks that emit them and the one that drains
/// them to RTT or semihosting. When full, new events are dropped and counted — the buffer keeps
/// the oldest, so the start of a burst that overran it stays readable — and the first event that
/// fits again is preceded by one [`TraceKind::EventsLost`] marker, so the gap shows in the trace
/// exactly where it happened.
#[derive(Clone, Debug)]
pub struct TraceBuffer<const N: usize> {
    events: heapless::Deque<TraceEvent, N>,
    lost: u32,
    lost_unreported: u32,
}

impl<const N: usize> Default for TraceBuffer<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> TraceBuffer<N> {
    /// An empty buffer.
    pub const fn new() -> Self {
        Self {
            events: heapless::Deque::new(),
            lost: 0,
            lost_unreported: 0,
        }
    }

    /// Adds an event; returns `false` (and counts it) if it did not fit.
    pub fn push(&mut self, event: TraceEvent) -> bool {
        if self.lost_unreported > 0 && N >= 2 {
            // The gap marker and the event go in together or not at all.
            if N.saturating_sub(self.events.len()) >= 2 {
                let marker = TraceEvent::new(
                    event.at_us,
                    TraceKind::EventsLost {
                        count: self.lost_unreported,
                    },
                );
                if self.events.push_back(marker).is_ok() {
                    self.lost_unreported = 0;
                }
            } else {
                self.count_lost();
                return false;
            }
        }
        match self.events.push_back(event) {
            Ok(()) => true,
            Err(_) => {
                self.count_lost();
                false
            }
        }
    }

    fn count_lost(&mut self) {
        self.lost = self.lost.saturating_add(1);
        self.lost_unreported = self.lost_unreported.saturating_add(1);
    }

    /// Takes the oldest event.
    pub fn pop(&mut self) -> Option<TraceEvent> {
        self.events.pop_front()
    }

    /// Events waiting.
    pub fn len(&self) -> usize {
        self.events.len()
    }

    /// True when nothing waits.
    pub fn is_empty(&self) -> bool {
        self.events.is_empty()
    }

    /// Events lost to a full buffer since boot.
    pub fn lost(&self) -> u32 {
        self.lost
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reject_reasons_follow_the_decoder() {
        let reason = RejectReason::from(DecodeError::ZeroSampleTime);
        assert_eq!(reason.name(), "zero-sample-time");
        assert_eq!(reason.index(), DecodeError::ZeroSampleTime.kind_index());
        assert_eq!(RejectReason::from_index(DecodeError::KINDS.len()), None);
    }
}
